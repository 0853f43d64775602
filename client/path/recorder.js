// @ts-check
// Recording: a keyframe of the walk's view as it starts, one every half second while it runs, and one as it
// stops; the spline smooths between them.

import { round } from "./keys.js";

const RECORD_EVERY_S = 0.5;
const seconds = (/** @type {number} */ ms) => round(ms / 1000);

export class Recorder {
  /**
   * `toggle` is the Record button. `hooks`: begin() empties the path (one step to undo); take(t) adds a
   * keyframe of the current view at `t` seconds.
   * @param {HTMLElement} toggle
   * @param {{begin: () => void, take: (t: number) => void}} hooks
   */
  constructor(toggle, hooks) {
    this.toggle = toggle;
    this.hooks = hooks;
    /** @type {{start: number, timer?: number} | null} */
    this.recording = null;
  }

  get active() {
    return this.recording !== null;
  }

  /** Start, or stop a recording under way. */
  record() {
    if (this.recording) return this.stop();
    this.hooks.begin();
    const recording = { start: performance.now(), timer: 0 };
    this.recording = recording;
    this.hooks.take(0);
    recording.timer = setInterval(() => this.hooks.take(seconds(performance.now() - recording.start)), RECORD_EVERY_S * 1000);
    this.show(true);
  }

  stop() {
    if (!this.recording) return;
    clearInterval(this.recording.timer);
    this.hooks.take(seconds(performance.now() - this.recording.start));
    this.recording = null;
    this.show(false);
  }

  /** @param {boolean} on */
  show(on) {
    this.toggle.textContent = on ? "Stop recording" : "Record";
    this.toggle.setAttribute("aria-pressed", String(on));
  }
}
