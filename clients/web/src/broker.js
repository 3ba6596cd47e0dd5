// The performer's stream through a NATS broker (docs/audience.md): the same handlers as
// PoseConnection (connection.js), fed from two subjects that `performer run --publish` fills:
// SUBJECT.frames (one binary frame per pose) and SUBJECT.meta (the hello and the stage's
// state as JSON text, repeated every second so a late viewer can start).
//
// Page parameters: broker=ws://HOST:PORT (the broker's WebSocket port), subject=performer.NAME
// (default performer.main; a trailing .frames is accepted), and the viewer account's
// user=...&pass=... or token=... nats.ws is loaded only when the page uses a broker.

import { decodeFrame, parseHello } from './protocol.js';
import { parseState } from './stage.js';

/** The broker settings of a page's query string, or null when it has no `broker`. */
export function brokerParams(search) {
  const params = new URLSearchParams(search);
  const url = params.get('broker');
  if (!url) return null;
  let subject = params.get('subject') || 'performer.main';
  subject = subject.replace(/\.(frames|meta)$/, '');
  const auth = {};
  if (params.get('user')) auth.user = params.get('user');
  if (params.get('pass')) auth.pass = params.get('pass');
  if (params.get('token')) auth.token = params.get('token');
  return { url, subject, auth };
}

export class BrokerConnection {
  /**
   * @param {{url: string, subject: string, auth: object}} settings brokerParams(location.search).
   * @param {object} handlers as PoseConnection's: onHello, onFrame, onState, onBadMessage, onPerformerState.
   */
  constructor(settings, handlers) {
    this.settings = settings;
    this.handlers = handlers;
    this.url = `${settings.url} ${settings.subject}`;
    this.hello = null;
    this._nc = null;
    this._stopped = false;
  }

  async start() {
    const { url, subject, auth } = this.settings;
    this.handlers.onState('connecting', `broker ${url}`);
    let connect;
    try {
      ({ connect } = await import('nats.ws'));
      this._nc = await connect({
        servers: url, ...auth, name: 'performer-viewer', reconnect: true, maxReconnectAttempts: -1,
        reconnectTimeWait: 500, waitOnFirstConnect: true, pingInterval: 10000,
      });
    } catch (err) {
      this.handlers.onState('error', `broker ${url}: ${err.message ?? err}`);
      return;
    }
    this._watch();
    this._read(`${subject}.meta`, (m) => this._meta(m.data));
    this._read(`${subject}.frames`, (m) => {
      if (!this.hello) return; // the hello comes within a second
      const data = m.data;
      this.handlers.onFrame(decodeFrame(data.buffer.slice(data.byteOffset, data.byteOffset + data.byteLength)),
        Date.now());
    });
  }

  stop() {
    this._stopped = true;
    this._nc?.close();
  }

  async _read(subject, onMessage) {
    const sub = this._nc.subscribe(subject);
    for await (const m of sub) {
      try {
        onMessage(m);
      } catch (err) {
        this.handlers.onBadMessage(err);
      }
    }
  }

  async _watch() {
    const url = this.settings.url;
    for await (const s of this._nc.status()) {
      if (s.type === 'disconnect') this.handlers.onState('closed', `broker ${url} went away`);
      else if (s.type === 'reconnecting') this.handlers.onState('waiting', `reconnecting to broker ${url}`);
      else if (s.type === 'reconnect' && this.hello) this.handlers.onState('open', this.url);
    }
  }

  _meta(data) {
    const msg = JSON.parse(new TextDecoder().decode(data));
    if (msg.type === 'hello') {
      if (this.hello) return; // repeated every second for late viewers
      this.hello = parseHello(msg);
      this.handlers.onHello(this.hello);
      this.handlers.onState('open', this.url);
    } else if (msg.type === 'state') {
      const text = JSON.stringify(msg);
      if (text === this._state) return; // repeated every second: only a change is news
      this._state = text;
      this.handlers.onPerformerState?.(parseState(msg));
    }
  }
}
