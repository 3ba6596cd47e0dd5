// WebSocket connection to `performer run` that reconnects by itself.
//
// After a close (server stopped, restarted, network gone) it retries after
// `minDelayMs`, doubling up to `maxDelayMs`; a hello resets the delay.

import { decodeFrame, frameFromJson, parseHello } from './protocol.js';
import { parseState } from './stage.js';

export class PoseConnection {
  /**
   * @param {string} url ws:// address of the stream (protocol.streamUrl).
   * @param {object} handlers onHello(hello), onFrame(frame, nowMs), onState(state, detail), onBadMessage(error),
   *     and optionally onPerformerState({width, depth, facing}) (the stage: stage.js).
   */
  constructor(url, handlers, { minDelayMs = 500, maxDelayMs = 5000 } = {}) {
    this.url = url;
    this.handlers = handlers;
    this.minDelayMs = minDelayMs;
    this.maxDelayMs = maxDelayMs;
    this.delayMs = minDelayMs;
    this.hello = null;
    this._ws = null;
    this._timer = null;
    this._stopped = false;
  }

  start() {
    this._stopped = false;
    this._open();
  }

  stop() {
    this._stopped = true;
    clearTimeout(this._timer);
    if (this._ws) this._ws.close(1000, 'viewer closed');
  }

  _open() {
    this.hello = null;
    this.handlers.onState('connecting', this.url);
    let ws;
    try {
      ws = new WebSocket(this.url);
    } catch (err) {
      this.handlers.onState('error', String(err));
      this._retry();
      return;
    }
    ws.binaryType = 'arraybuffer';
    ws.onmessage = (ev) => this._message(ev.data);
    ws.onclose = (ev) => {
      this._ws = null;
      if (this._stopped) return;
      const why = ev.reason ? `${ev.code} ${ev.reason}` : `code ${ev.code}`;
      this.handlers.onState('closed', why);
      this._retry();
    };
    this._ws = ws;
  }

  _retry() {
    if (this._stopped) return;
    const delay = this.delayMs;
    this.delayMs = Math.min(this.maxDelayMs, this.delayMs * 2);
    this.handlers.onState('waiting', `reconnecting in ${(delay / 1000).toFixed(1)} s`);
    this._timer = setTimeout(() => this._open(), delay);
  }

  _message(data) {
    const now = Date.now();
    try {
      if (typeof data !== 'string') {
        if (this.hello) this.handlers.onFrame(decodeFrame(data), now);
        return;
      }
      const msg = JSON.parse(data);
      if (msg.type === 'hello') {
        this.hello = parseHello(msg);
        this.delayMs = this.minDelayMs;
        this.handlers.onHello(this.hello);
        this.handlers.onState('open', this.url);
      } else if (msg.type === 'frame' && this.hello) {
        this.handlers.onFrame(frameFromJson(msg), now);
      } else if (msg.type === 'state') {
        this.handlers.onPerformerState?.(parseState(msg));
      } else if (msg.type === 'error') {
        this.handlers.onBadMessage(new Error(`server: ${msg.error}`));
      }
    } catch (err) {
      this.handlers.onBadMessage(err);
    }
  }
}
