// The show desk (docs/show.md, "The show desk"): watch what the performer hears and does, and steer it.
// Connects to ws://HOST:PORT/desk (or ?ws=URL), receives {"type": "status"} a few times a second
// (realtime/desk.py) and sends the control messages of docs/protocol.md. Every value shown is the one
// the engine reports it applied, never the one sent. Steering needs the server's token (?token= or
// the token field); without it the desk watches. Test hook: window.deskState.
const params = new URLSearchParams(location.search);
const wsUrl = params.get('ws') || `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/desk`;
const $ = (id) => document.getElementById(id);
const state = {
  conn: 'connecting', connects: 0, control: false, tokenRejected: false, message: '', status: null,
  statuses: 0, sent: 0, replies: [],
};
window.deskState = state;
let token = params.get('token') || sessionStorage.getItem('performer-desk-token') || '';
let ws = null;
let retry = null;
const strips = new Map(); // performer name -> {el, beat: {phase, bpm, at}}
const editing = new WeakSet(); // sliders held by the user: not overwritten by the status

function say(text, bad = false) {
  state.message = text;
  $('message').textContent = text;
  $('message').className = bad ? 'message bad' : 'message';
}

function setConn(text, kind) {
  state.conn = text;
  $('conn').textContent = text;
  $('conn').className = `badge ${kind}`;
}

function setMode() {
  $('mode').textContent = state.control ? 'steering' : (state.tokenRejected ? 'watching only: wrong token' : 'watching only');
  document.body.classList.toggle('locked', !state.control);
}

function connect(useToken) {
  setConn(state.connects ? 'reconnecting' : 'connecting', 'warn');
  ws = new WebSocket(`${wsUrl}?format=json`);
  const sock = ws;
  sock.onopen = () => {
    state.connects += 1;
    setConn(state.connects > 1 ? 'reconnected' : 'connected', 'ok');
    if (state.connects > 1 && !state.tokenRejected) say(`engine back: connection ${state.connects}`);
    if (useToken && token) sock.send(JSON.stringify({ type: 'auth', token }));
  };
  sock.onmessage = (ev) => {
    if (typeof ev.data !== 'string') return;
    let msg;
    try { msg = JSON.parse(ev.data); } catch { return; }
    onMessage(msg);
  };
  sock.onclose = (ev) => {
    if (sock !== ws) return;
    state.control = false;
    setMode();
    if (ev.code === 1008 && /token/.test(ev.reason)) {
      if (useToken && token) {
        state.tokenRejected = true;
        say('wrong token: this desk cannot steer (watching only if the show lets viewers in)', true);
        setConn('token refused', 'bad');
        retry = setTimeout(() => connect(false), 300);
        return;
      }
      say('this show needs the token even to watch: enter it and press steer', true);
      setConn('needs token', 'bad');
      return;
    }
    setConn('engine gone: reconnecting', 'bad');
    retry = setTimeout(() => connect(useToken), 1000);
  };
}

function onMessage(msg) {
  if (msg.type === 'hello') {
    state.control = !!msg.control;
    setMode();
  } else if (msg.type === 'auth_ok') {
    state.control = !!msg.control;
    state.tokenRejected = false;
    setMode();
    say(state.control ? 'steering: controls are live' : 'token accepted, but this engine takes no control');
  } else if (msg.type === 'status') {
    state.status = msg;
    state.statuses += 1;
    render(msg);
  } else if (msg.type === 'control_ok') {
    state.replies.push(msg);
  } else if (msg.type === 'error') {
    state.replies.push(msg);
    say(msg.error, true);
  }
}

function send(performer, action, value) {
  if (!ws || ws.readyState !== WebSocket.OPEN) { say('not connected', true); return; }
  if (!state.control) say(state.tokenRejected ? 'wrong token: cannot steer' : 'steering needs the token', true);
  const msg = { type: 'control', action, performer };
  if (value !== undefined) msg.value = value;
  ws.send(JSON.stringify(msg));
  state.sent += 1;
}

const fmt = (v, digits = 1) => (v === null || v === undefined ? '-' : Number(v).toFixed(digits));

function strip(name) {
  let s = strips.get(name);
  if (s) return s;
  const el = $('strip').content.firstElementChild.cloneNode(true);
  el.dataset.performer = name;
  el.querySelector('.name').textContent = name;
  const q = (sel) => el.querySelector(sel);
  for (const b of el.querySelectorAll('[data-idle]')) b.onclick = () => send(name, 'idle', Number(b.dataset.idle));
  q('.style').onchange = (e) => send(name, 'style', e.target.value);
  q('.stage').onchange = (e) => send(name, 'stage', e.target.value);
  q('.facing').onchange = (e) => send(name, 'facing', e.target.value);
  q('.home').onclick = () => send(name, 'home');
  for (const [cls, action] of [['.energy', 'energy'], ['.lead', 'lead']]) {
    const input = q(cls);
    input.addEventListener('pointerdown', () => editing.add(input));
    input.addEventListener('input', () => editing.add(input));
    input.addEventListener('change', () => { editing.delete(input); send(name, action, Number(input.value)); });
  }
  $('strips').appendChild(el);
  s = { el, beat: { phase: NaN, bpm: 0, at: 0 } };
  strips.set(name, s);
  return s;
}

function render(st) {
  $('input').textContent = `${st.input} · ${st.state}`;
  const level = st.level_dbfs;
  $('level').textContent = level <= -120 ? '-inf dBFS' : `${level.toFixed(1)} dBFS`;
  const pos = (db) => `${Math.max(0, Math.min(100, (db + 60) / 60 * 100))}%`;
  $('level-bar').style.width = pos(level);
  $('peak-tick').style.left = pos(st.peak_dbfs);
  $('fps').textContent = fmt(st.fps);
  $('hop').textContent = fmt(st.hop_p99_ms, 2);
  $('latency').textContent = fmt(st.latency_p99_ms, 1);
  $('overruns').textContent = st.overruns;
  for (const p of st.performers) {
    const s = strip(p.name);
    const q = (sel) => s.el.querySelector(sel);
    q('.music').classList.toggle('on', !!p.music);
    q('.heard').textContent = p.music === null ? '' : `${p.music ? 'music' : 'no music'} · heard ${p.heard}`;
    q('.bpm').textContent = p.tempo_bpm ? p.tempo_bpm.toFixed(1) : '-';
    q('.rate').textContent = fmt(p.rate, 2);
    s.beat = { phase: p.beat_phase ?? NaN, bpm: p.tempo_bpm || 0, at: performance.now() };
    q('.dance').classList.toggle('active', !p.idle);
    q('.idle').classList.toggle('active', p.idle);
    const w = p.idle_weight;
    q('.state-text').textContent = p.idle ? (w !== null && w < 1 ? 'settling' : 'holding the idle')
      : (p.music === false ? 'idle: no music' : 'dancing');
    setSelect(q('.style'), p.style, p.style === null);
    q('.style-now').textContent = p.style_now || '-';
    setRange(q('.energy'), p.energy);
    q('.energy-val').textContent = fmt(p.energy, 2);
    setRange(q('.lead'), p.lead_ms);
    q('.lead-val').textContent = p.lead_ms === null ? '-' : `${Math.round(p.lead_ms)}`;
    const stage = Array.isArray(p.stage) ? `${p.stage[0]}x${p.stage[1]}` : (p.stage === null ? null : '0');
    setSelect(q('.stage'), stage, p.stage === null);
    setSelect(q('.facing'), p.facing, p.facing === null);
    q('.stage-now').textContent = stage === '0' ? 'in place' : (stage ? `${stage} m, ${p.facing}` : '-');
    q('.frames').textContent = p.frames;
    q('.p-hop').textContent = fmt(p.hop_p99_ms, 2);
    q('.drops').textContent = p.drops;
    const list = q('.receivers');
    list.replaceChildren(...p.receivers.map((r) => {
      const li = document.createElement('li');
      li.textContent = `${r.name}: ${r.state}`;
      if (r.state === 'no receiver') li.className = 'nobody';
      return li;
    }));
  }
}

function setRange(input, value) {
  input.disabled = value === null;
  if (value !== null && !editing.has(input)) input.value = value;
}

function setSelect(select, value, disabled) {
  select.disabled = disabled;
  if (value === null || document.activeElement === select) return;
  if (![...select.options].some((o) => (o.value || o.text) === value)) select.add(new Option(value, value));
  select.value = value;
}

function beatLights(now) {
  for (const s of strips.values()) {
    const { phase, bpm, at } = s.beat;
    const on = Number.isFinite(phase) && bpm > 0 && ((phase + (now - at) / 1000 * bpm / 60) % 1) < 0.18;
    s.el.querySelector('.beat').classList.toggle('on', on);
  }
  requestAnimationFrame(beatLights);
}

$('token').value = token;
$('steer').onclick = () => {
  token = $('token').value;
  sessionStorage.setItem('performer-desk-token', token);
  state.tokenRejected = false;
  clearTimeout(retry);
  if (ws) { ws.onclose = null; ws.close(); }
  ws = null;
  connect(true);
};
setMode();
connect(true);
requestAnimationFrame(beatLights);
