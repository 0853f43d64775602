// @ts-check
// The overlay of live numbers: frames shown per second, latency (camera message sent -> the first frame
// showing that camera drawn, median of the last 31), the last frame's size, scale, render time, phase,
// iteration and samples, and the connection's state.

const LATENCY_SAMPLES = 31;
/** @param {string} id @returns {any} */
const $ = (id) => document.getElementById(id);
/** The overlay's rows of a class. @param {string} selector @returns {NodeListOf<HTMLElement>} */
const rows = (selector) => document.querySelectorAll(`#overlay ${selector}`);

function median(values) {
  if (!values.length) return null;
  const sorted = [...values].sort((a, b) => a - b);
  const mid = sorted.length >> 1;
  return sorted.length % 2 ? sorted[mid] : (sorted[mid - 1] + sorted[mid]) / 2;
}

export class Overlay {
  constructor() {
    this.frames = 0; // frames drawn since the page opened
    this.shownAt = []; // when each frame of the last second was drawn (ms)
    this.latencies = []; // ms, the last LATENCY_SAMPLES
    this.sentAt = new Map(); // camera id -> when it was sent (ms), until a frame shows it or a newer one
    this.frame = null; // the description of the frame shown
    this.view = null; // the 360° view or a headset drawing locally: {label, drawnAt: ms of each draw, last second}
  }

  /** The 360° view or a headset ("360°", "VR") has drawn `total` frames so far; null `label`: the flat view. */
  viewDrawn(label, total, now) {
    if (label === null) {
      this.view = null;
      return;
    }
    if (this.view?.label !== label) this.view = { label, total, drawnAt: [] };
    for (let k = this.view.total; k < total; k++) this.view.drawnAt.push(now);
    this.view.total = total;
  }

  cameraSent(id) {
    this.sentAt.set(id, performance.now());
  }

  frameShown(meta) {
    const now = performance.now();
    this.frames += 1;
    this.shownAt.push(now);
    this.frame = meta;
    const sentAt = this.sentAt.get(meta.camera_id);
    if (sentAt === undefined) return; // no camera, or one already shown
    this.latencies.push(now - sentAt);
    if (this.latencies.length > LATENCY_SAMPLES) this.latencies.shift();
    for (const id of this.sentAt.keys()) if (id <= meta.camera_id) this.sentAt.delete(id); // never shown: replaced
  }

  connection(state, detail) {
    const words = {
      connecting: "connecting…",
      open: "connected",
      waiting: `${detail.why} · retry in ${detail.seconds?.toFixed(1)} s`,
      refused: `refused: ${detail.why}`,
      held: `${detail.why} · ${detail.seconds} s`,
      offered: detail.why,
      stopped: "stopped",
    };
    $("o-connection").textContent = words[state] ?? state;
    $("o-retry").hidden = state !== "offered"; // the time the server asked for has passed
    $("overlay").dataset.connection = state;
  }

  /** The walker's rows: the gamepad in use (null: none) and the body that keeps it clear (null: collide off). */
  walker(pad, body) {
    for (const row of rows(".pad-row")) row.hidden = pad === null;
    if (pad !== null) $("o-pad").textContent = pad.length > 28 ? `${pad.slice(0, 27)}…` : pad;
    for (const row of rows(".body-row")) row.hidden = !body;
    if (body) {
      const size = (x) => Number(x.toPrecision(2));
      if (body.radius === 0) $("o-body").textContent = "nothing to walk into";
      else if (body.height) {
        $("o-body").textContent = `r ${size(body.radius)} · eye ${size(body.height)}${body.standing ? "" : " · in the air"}`;
      } else $("o-body").textContent = `r ${size(body.radius)} · flying`;
    }
  }

  /** Refresh the numbers (a few times a second is enough to read them). */
  update(now) {
    while (this.shownAt.length && this.shownAt[0] < now - 1000) this.shownAt.shift();
    const latency = median(this.latencies);
    $("o-fps").textContent = String(this.shownAt.length);
    $("o-latency").textContent = latency === null ? "–" : `${Math.round(latency)} ms`;
    $("o-frames").textContent = String(this.frames);
    for (const row of rows(".view-row")) row.hidden = this.view === null;
    if (this.view) {
      const drawnAt = this.view.drawnAt;
      while (drawnAt.length && drawnAt[0] < now - 1000) drawnAt.shift();
      $("o-view").textContent = `${this.view.label} · ${drawnAt.length} a second`; // drawn here, no server
    }
    const f = this.frame;
    if (!f) return;
    $("o-size").textContent = `${f.width}×${f.height}`;
    $("o-scale").textContent = f.scale === 1 ? "full" : `×${f.scale.toFixed(2)}`;
    $("o-render").textContent = `${Math.round(f.render_ms)} ms`;
    $("o-phase").textContent = f.phase === "refine" ? (f.final ? "refined" : "refining") : "walk";
    $("o-phase").dataset.phase = f.final ? "final" : f.phase;
    $("o-iteration").textContent = `${f.iteration}${f.temporal ? " (temporal)" : ""}`;
    $("o-spp").textContent = f.spp;
    $("o-dropped").textContent = f.dropped;
  }
}
