// The WebSocket to /ws, reconnected with exponential backoff whenever it drops.
//
// Frames arrive as a `frame` text message followed by one binary JPEG (or one per band: bands.js); handed on together.
// The owner restores the walk-through (scene, camera, settings) in `onOpen`, as after any fresh start.

import { FrameParts } from "./bands.js";

const BACKOFF_MS = [250, 8000]; // first retry, longest wait
const CLOSED_BECAUSE = { 1001: "server going away", 1006: "connection lost", 1012: "server restarting", 1013: "server busy" };

export class Connection {
  /**
   * @param {string} url        ws:// or wss:// address of the walk-through
   * @param {object} handlers   onOpen(), onMessage(msg), onFrame(meta, jpeg ArrayBuffer), onState(state, detail)
   */
  constructor(url, handlers) {
    this.url = url;
    this.handlers = handlers;
    this.socket = null;
    this.state = "idle"; // connecting | open | waiting (to reconnect) | refused | stopped
    this.backoff = BACKOFF_MS[0];
    this.opens = 0; // connections opened so far (the tests watch reconnection through it)
    this.parts = new FrameParts(); // the frame description waiting for its JPEG (or its bands')
    this.timer = null;
  }

  start() {
    this.stopped = false;
    this.connect();
  }

  stop() {
    this.stopped = true;
    clearTimeout(this.timer);
    this.socket?.close(1000, "client stopped");
    this.setState("stopped");
  }

  /** The server accepted the session: the next drop retries quickly again. */
  healthy() {
    this.backoff = BACKOFF_MS[0];
  }

  send(msg) {
    if (this.socket?.readyState !== WebSocket.OPEN) return false;
    this.socket.send(JSON.stringify(msg));
    return true;
  }

  connect() {
    clearTimeout(this.timer);
    this.setState("connecting");
    const socket = new WebSocket(this.url);
    socket.binaryType = "arraybuffer";
    this.socket = socket;
    this.meta = null;
    socket.onopen = () => {
      this.opens += 1;
      this.setState("open");
      this.handlers.onOpen();
    };
    socket.onmessage = (event) => this.receive(event.data);
    socket.onclose = (event) => {
      if (socket !== this.socket || this.stopped) return;
      if (event.code === 1008) this.refused(event.reason); // no token, or a foreign page: retrying cannot help
      else this.retry(event);
    };
  }

  receive(data) {
    if (typeof data !== "string") {
      const frame = this.parts.take(data); // one JPEG, or a band's each (bands.js)
      if (frame) this.handlers.onFrame(...frame);
      return;
    }
    let msg;
    try {
      msg = JSON.parse(data);
    } catch {
      this.handlers.onMessage({ type: "error", message: "the server sent a message that is not JSON" });
      return;
    }
    if (msg.type === "frame") this.parts.expect(msg);
    else this.handlers.onMessage(msg);
  }

  refused(reason) {
    this.stopped = true;
    this.setState("refused", { why: reason });
  }

  retry(event) {
    const wait = this.backoff * (0.8 + 0.4 * Math.random()); // jitter: many clients do not return at once
    this.backoff = Math.min(this.backoff * 2, BACKOFF_MS[1]);
    // a server that restarts says how far its start is (rcp_server/service/startup.py): "starting: compiling kernels (3/14)"
    const starting = event.code === 1013 && /^the server is starting: ([^;]*)/.exec(event.reason);
    const why = starting ? `starting: ${starting[1]}` : (CLOSED_BECAUSE[event.code] ?? `closed (${event.code})`);
    this.setState("waiting", { why, seconds: wait / 1000 });
    this.timer = setTimeout(() => this.connect(), wait);
  }

  setState(state, detail = {}) {
    this.state = state;
    this.handlers.onState(state, detail);
  }
}
