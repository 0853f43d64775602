// @ts-check
// The WebSocket to /ws, reconnected with exponential backoff whenever it drops.
//
// Frames arrive as a `frame` text message followed by one binary JPEG (or one per band: bands.js); handed on together.
// The owner restores the walk-through (scene, camera, settings) in `onOpen`, as after any fresh start.
//
// A server that refuses a walker closes its socket at once with the reason, in one line. A reason that says
// when to come back ("... try again in 17 s"), with close code 1013 (try again later), 1008 (policy) or an
// application's 4xxx, holds the page that long (state `held`), then offers to try again (state `offered`:
// `start()` does); 1008 or 4xxx without one is final (`refused`: no token, a foreign page). The server's own
// start ("the server is starting: ...", 1013) is waited out without asking.

import { FrameParts } from "./bands.js";

const BACKOFF_MS = [250, 8000]; // first retry, longest wait
const CLOSED_BECAUSE = { 1001: "server going away", 1006: "connection lost", 1012: "server restarting", 1013: "server busy" };
const REASON_CHARS = 200; // of a close reason, shown in one line
const STARTING = /^the server is starting: ([^;]*)/;

/**
 * The seconds a close reason asks the client to wait ("... try again in 17 s"), or null when it names none.
 * @param {string} reason
 * @returns {number | null}
 */
export function retryAfter(reason) {
  const found = /try again in (\d+(?:\.\d+)?) ?s\b/i.exec(reason);
  const seconds = found ? Number(found[1]) : NaN;
  return Number.isFinite(seconds) ? seconds : null;
}

/**
 * What a close means: retry with backoff, hold for the stated time, or refused for good.
 * @param {number} code
 * @param {string} reason
 * @returns {"retry" | "hold" | "refused"}
 */
export function closeMeaning(code, reason) {
  const hinted = retryAfter(reason) !== null;
  const application = code >= 4000 && code <= 4999;
  if (code === 1013) return hinted && !STARTING.test(reason) ? "hold" : "retry";
  if (code === 1008 || application) return hinted ? "hold" : "refused";
  return "retry";
}

/** A close reason as one line the page shows. @param {string} reason */
function oneLine(reason) {
  const line = reason.split(/[\r\n]/)[0].trim();
  return line.length > REASON_CHARS ? `${line.slice(0, REASON_CHARS - 1)}…` : line;
}

export class Connection {
  /**
   * @param {string} url        ws:// or wss:// address of the walk-through
   * @param {object} handlers   onOpen(), onMessage(msg), onFrame(meta, jpeg ArrayBuffer), onState(state, detail)
   */
  constructor(url, handlers) {
    this.url = url;
    this.handlers = handlers;
    this.socket = null;
    this.state = "idle"; // connecting | open | waiting (to reconnect) | held | offered | refused | stopped
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
      const meaning = closeMeaning(event.code, event.reason);
      if (meaning === "refused") this.refused(event.reason); // no token, or a foreign page: retrying cannot help
      else if (meaning === "hold") this.hold(event.reason);
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
    this.setState("refused", { why: oneLine(reason) });
  }

  /** Refused for now: the reason's line, then, once its time has passed, the offer to try again. */
  hold(reason) {
    this.stopped = true;
    const why = oneLine(reason);
    const seconds = retryAfter(reason) ?? 0;
    this.setState("held", { why, seconds });
    this.timer = setTimeout(() => this.setState("offered", { why }), seconds * 1000);
  }

  retry(event) {
    const wait = this.backoff * (0.8 + 0.4 * Math.random()); // jitter: many clients do not return at once
    this.backoff = Math.min(this.backoff * 2, BACKOFF_MS[1]);
    // a server that restarts says how far its start is (rcp_server/service/startup.py): "starting: compiling kernels (3/14)"
    const starting = event.code === 1013 && STARTING.exec(event.reason);
    const why = starting ? `starting: ${starting[1]}` : (CLOSED_BECAUSE[event.code] ?? `closed (${event.code})`);
    this.setState("waiting", { why, seconds: wait / 1000 });
    this.timer = setTimeout(() => this.connect(), wait);
  }

  setState(state, detail = {}) {
    this.state = state;
    this.handlers.onState(state, detail);
  }
}
