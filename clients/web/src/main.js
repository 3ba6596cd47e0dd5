// live-performer web viewer: connects to `performer run`'s WebSocket stream and
// animates a procedural humanoid, or a VRM avatar (dropped on the page, picked
// with the button, or named by ?vrm=URL).
//
// URL parameters: ws=ws://HOST:PORT/ws (default: the serving host), token=SECRET,
// format=binary|json, vrm=URL; or, for an audience through a NATS broker (broker.js,
// docs/audience.md), broker=ws://HOST:PORT&subject=performer.NAME&user=...&pass=... The
// HUD's "source" says which. The stage (docs/stage.md) is drawn on the floor when the
// server says it, and the camera follows the performer across it (the 'follow' box); in an
// ensemble every performer's spot is drawn too, this one's brighter, and the camera, which
// frames the whole stage, follows its performer within its spot.
//
// For tests and tinkering the page exposes window.performerStats (updated with
// every frame) and window.performer (boneQuaternion, jointPositions, loadVrm).

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { BrokerConnection, brokerParams } from './broker.js';
import { PoseConnection } from './connection.js';
import { Hud } from './hud.js';
import { streamUrl } from './protocol.js';
import { ProceduralAvatar } from './skeleton.js';
import { fitDistance, followStep, StageOutline } from './stage.js';
import { StreamStats } from './stats.js';
import { loadVrm, VrmAvatar } from './vrm.js';

const TRAIL_BONES = ['LeftHand', 'RightHand', 'LeftFoot', 'RightFoot'];
const TRAIL_FRAMES = 45; // 1.5 s at 30 fps

const params = new URLSearchParams(location.search);
const hud = new Hud(document);
const stats = new StreamStats();
const world = createWorld(document.getElementById('view'));

let hello = null;
let procedural = null; // always animated; hidden while a VRM is shown
let vrm = null; // the loaded VRM (kept across reconnects)
let vrmAvatar = null;
let vrmName = '';
let latest = null; // the newest frame not yet drawn
const trails = createTrails(world.scene);
const outline = new StageOutline(THREE, world.scene);
let stageState = null; // {width, depth, facing, spot, spots} from the server's state messages (stage.js)

function publishStats() {
  window.performerStats = {
    ...stats.snapshot(),
    avatar: vrmAvatar ? `vrm:${vrmName}` : procedural ? 'procedural' : 'none',
    vrmMissingBones: vrmAvatar ? vrmAvatar.missing : [],
    bones: hello ? hello.bones.length : 0,
    webgl: world.renderer !== null,
    pictures, // pictures drawn by WebGL since the page loaded
    framesShown, // stream frames applied to the avatars (at most one per picture)
    url: connection.url,
    source,
    stage: stageState ? [stageState.width, stageState.depth] : null,
    facing: stageState?.facing ?? null,
    spot: stageState?.spot ? [stageState.spot.x, stageState.spot.z, stageState.spot.width, stageState.spot.depth] : null,
    target: world.controls.target.toArray(),
  };
}

function onHello(h) {
  hello = h;
  stats.reset(h.bones.length);
  procedural?.dispose();
  procedural = new ProceduralAvatar(h);
  world.scene.add(procedural.root);
  if (vrm) useVrm(vrm, vrmName);
  publishStats();
}

function onFrame(frame, nowMs) {
  stats.onFrame(frame, nowMs);
  latest = frame;
  publishStats();
}

function useVrm(loaded, name) {
  vrmAvatar?.root.removeFromParent();
  vrm = loaded;
  vrmName = name;
  if (!hello) return; // mapped when the hello arrives
  vrmAvatar = new VrmAvatar(loaded, hello);
  world.scene.add(vrmAvatar.root);
  procedural.root.visible = document.getElementById('show-skeleton').checked;
  dirty = true;
  const missing = vrmAvatar.missing.length ? ` (no ${vrmAvatar.missing.join(', ')}: folded into children)` : '';
  hud.message(`VRM ${name}${missing}`);
  publishStats();
}

async function openVrm(source, name) {
  hud.message(`loading VRM ${name}...`);
  try {
    useVrm(await loadVrm(source), name);
  } catch (err) {
    console.warn('cannot load VRM', name, err);
    hud.message(`cannot load VRM ${name}: ${err.message ?? err}`);
  }
}

/** The stage changed: draw it, and the first time frame the camera on it. */
function onPerformerState(state) {
  const first = stageState === null;
  stageState = state;
  outline.set(state);
  if (first && state.width > 0 && state.depth > 0) {
    const { camera, controls } = world;
    const dist = fitDistance(state.width, state.depth, camera.fov, camera.aspect);
    const dir = camera.position.clone().sub(controls.target).normalize();
    camera.position.copy(controls.target).addScaledVector(dir, dist);
    controls.update();
  }
  dirty = true;
  publishStats();
}

const handlers = {
  onHello,
  onFrame,
  onPerformerState,
  onState(state, detail) {
    stats.state = state;
    if (state === 'open') stats.connects += 1;
    if (state === 'closed' || state === 'error') stats.lastError = detail;
    hud.setState(state, detail);
    publishStats();
  },
  onBadMessage(err) {
    stats.badFrames += 1;
    stats.lastError = String(err.message ?? err);
    console.warn('bad message from the server:', err);
  },
};
const broker = brokerParams(location.search);
const connection = broker ? new BrokerConnection(broker, handlers) : new PoseConnection(streamUrl(location), handlers);
const source = broker ? 'broker' : 'performer run';
document.getElementById('source').textContent = source;

// ---- VRM from the URL, the file button, or a dropped file ----------------------------

/** A short display name for a VRM URL. */
const nameOf = (url) => (url.startsWith('data:') ? 'data URL' : url.split('?')[0].split('/').pop());

if (params.get('vrm')) openVrm(params.get('vrm'), nameOf(params.get('vrm')));
const picker = document.getElementById('vrm-file');
document.getElementById('load-vrm').addEventListener('click', () => picker.click());
picker.addEventListener('change', async () => {
  const file = picker.files[0];
  if (file) openVrm(await file.arrayBuffer(), file.name);
});
window.addEventListener('dragover', (ev) => ev.preventDefault());
window.addEventListener('drop', async (ev) => {
  ev.preventDefault();
  const file = ev.dataTransfer?.files[0];
  if (file) openVrm(await file.arrayBuffer(), file.name);
});
document.getElementById('show-skeleton').addEventListener('change', (ev) => {
  if (procedural) procedural.root.visible = ev.target.checked || !vrmAvatar;
  dirty = true;
});

// ---- scene ---------------------------------------------------------------------------

function createWorld(container) {
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x1b1f29);
  const camera = new THREE.PerspectiveCamera(40, 1, 0.05, 100);
  camera.position.set(0.6, 1.4, 4.2); // in front of the performer, who faces +Z
  let renderer = null;
  try {
    // A software rasteriser (no GPU: SwiftShader, llvmpipe) gets no antialiasing and
    // one pixel per CSS pixel, which keeps it near 30 pictures a second.
    const software = softwareGl();
    renderer = new THREE.WebGLRenderer({ antialias: !software });
    renderer.setPixelRatio(software ? 1 : Math.min(2, window.devicePixelRatio));
    container.appendChild(renderer.domElement);
  } catch (err) {
    hud.message(`no WebGL in this browser (${err.message ?? err}); stream statistics still update`);
  }
  const controls = new OrbitControls(camera, renderer ? renderer.domElement : container);
  controls.target.set(0, 0.9, 0);
  controls.enableDamping = true;
  controls.update();
  scene.add(new THREE.HemisphereLight(0xdde6ff, 0x30343d, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.8);
  sun.position.set(2, 4, 3);
  scene.add(sun);
  const grid = new THREE.GridHelper(6, 12, 0x59627a, 0x343a4a); // 0.5 m squares
  scene.add(grid);
  const resize = () => {
    const w = container.clientWidth || window.innerWidth, h = container.clientHeight || window.innerHeight;
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    renderer?.setSize(w, h);
  };
  window.addEventListener('resize', resize);
  resize();
  return { scene, camera, renderer, controls };
}

function softwareGl() {
  const gl = document.createElement('canvas').getContext('webgl2') ?? document.createElement('canvas').getContext('webgl');
  if (!gl) return false;
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
  gl.getExtension('WEBGL_lose_context')?.loseContext();
  return /swiftshader|llvmpipe|software/i.test(name);
}

function createTrails(scene) {
  return TRAIL_BONES.map((name) => {
    const positions = new Float32Array(3 * TRAIL_FRAMES);
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    geometry.setDrawRange(0, 0);
    const color = name.startsWith('Left') ? 0xffb27a : 0x8fd0ff;
    const line = new THREE.Line(geometry, new THREE.LineBasicMaterial({ color, transparent: true, opacity: 0.8 }));
    line.frustumCulled = false;
    scene.add(line);
    return { name, positions, geometry, count: 0 };
  });
}

const _p = new THREE.Vector3();
function pushTrails(avatar) {
  for (const t of trails) {
    if (!avatar.worldPosition(t.name, _p)) continue;
    t.positions.copyWithin(3, 0, 3 * (TRAIL_FRAMES - 1));
    _p.toArray(t.positions, 0);
    t.count = Math.min(TRAIL_FRAMES, t.count + 1);
    t.geometry.setDrawRange(0, t.count);
    t.geometry.attributes.position.needsUpdate = true;
  }
}

// The follow camera: the orbit target (and the camera with it) drifts after the performer's
// hips across the floor, so a travelling performer stays in the picture (stage.js).
const _hips = new THREE.Vector3();
function follow(avatar) {
  if (!document.getElementById('follow').checked || !avatar.worldPosition('Hips', _hips)) return;
  const { camera, controls } = world;
  const bound = stageState?.spot?.width > 0 ? stageState.spot : stageState; // an ensemble's: its own spot
  const [dx, dz] = followStep([controls.target.x, controls.target.z], _hips.x, _hips.z, 0.08, bound);
  controls.target.x += dx;
  controls.target.z += dz;
  camera.position.x += dx;
  camera.position.z += dz;
}

// ---- render loop ---------------------------------------------------------------------

// Draw only when something changed (a new frame, the camera, the window): a software
// renderer (no GPU) then spends its time on at most 30 pictures a second.
let dirty = true;
world.controls.addEventListener('change', () => { dirty = true; });
window.addEventListener('resize', () => { dirty = true; });
let pictures = 0;
let framesShown = 0;
let lastFrameMs = performance.now();
function animate(now) {
  requestAnimationFrame(animate);
  if (latest && procedural) {
    procedural.apply(latest);
    vrmAvatar?.apply(latest);
    latest = null;
    framesShown += 1;
    vrmAvatar?.update(Math.min(0.1, (now - lastFrameMs) / 1000)); // spring bones; normalized -> mesh bones
    lastFrameMs = now;
    world.scene.updateMatrixWorld();
    pushTrails(vrmAvatar ?? procedural);
    follow(vrmAvatar ?? procedural);
    dirty = true;
  }
  world.controls.update();
  if (dirty && world.renderer) {
    world.renderer.render(world.scene, world.camera);
    pictures += 1;
  }
  dirty = false;
}

// The readouts refresh on a timer, not in the render loop, so they stay current when a
// busy machine draws few pictures.
setInterval(() => {
  stats.tick(Date.now());
  hud.update(stats, vrmAvatar ? vrmName : 'procedural humanoid');
  if (hello) hud.drawSpeeds(hello.jointNames, stats.speeds);
  publishStats();
}, 250);

// ---- test and console hooks ----------------------------------------------------------

window.performer = {
  /** Local quaternion [x, y, z, w] of a bone on the procedural avatar (as streamed). */
  boneQuaternion(name) {
    const node = procedural?.nodes[hello.bones.indexOf(name)];
    return node ? node.quaternion.toArray() : null;
  },
  /** World joint positions [x, y, z] (metres) on both avatars, after the last drawn frame. */
  jointPositions(names = hello?.bones ?? []) {
    world.scene.updateMatrixWorld();
    const out = { procedural: {}, vrm: vrmAvatar ? {} : null };
    for (const n of names) {
      out.procedural[n] = procedural?.worldPosition(n).toArray() ?? null;
      if (vrmAvatar) out.vrm[n] = vrmAvatar.worldPosition(n)?.toArray() ?? null;
    }
    return out;
  },
  loadVrm: (url) => openVrm(url, nameOf(url)),
  /** The stage rectangle's corners [[x, z], ...] as drawn on the floor, or null when none is shown. */
  stageOutline() {
    return outline.drawn().stage;
  },
  /** In an ensemble: {spot: this performer's spot's corners (or null), others: the other spots'}. */
  spotOutlines() {
    const { spot, others } = outline.drawn();
    return { spot, others };
  },
};

publishStats();
connection.start();
requestAnimationFrame(animate);
