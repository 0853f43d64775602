// @ts-check
// The path's keyframes, the one selected, and undo: every change goes through here, taken as one step to undo
// (path/history.js), and `changed()` redraws the panel after it.

import { History } from "./history.js";

export const round = (/** @type {number} */ x) => Math.round(x * 1e4) / 1e4;

/**
 * A keyframe at `t` seconds of the view `camera` ({eye, look_at, up, fov}, and a panorama's projection and
 * stereo in the 360° view: a 360° video).
 * @param {any} camera @param {number} t
 */
export function keyOf(camera, t) {
  const { eye, look_at, up, fov, projection, stereo } = camera;
  const kind = projection ? { projection, stereo } : {};
  return { t, eye: eye.map(round), look_at: look_at.map(round), up: [...up], fov: round(fov), ...kind };
}

export class PathKeys {
  /** @param {() => void} changed called after every change */
  constructor(changed) {
    this.path = { fps: 24, loop: false, keyframes: /** @type {any[]} */ ([]) };
    this.selected = -1; // the keyframe shown in the editor
    this.changed = changed;
    this.history = new History(
      () => this.path.keyframes,
      (keys) => {
        this.path.keyframes = keys;
        this.selected = Math.min(this.selected, keys.length - 1);
        changed();
      },
    );
  }

  get keyframes() {
    return this.path.keyframes;
  }

  /** The time a new keyframe takes: a second after the last. */
  next() {
    const last = this.path.keyframes.at(-1);
    return last ? round(last.t + 1) : 0;
  }

  /** `key` appended (`step`: one step to undo; a recording takes one as it starts). */
  push(key, step = true) {
    if (step) this.history.record();
    this.path.keyframes.push(key);
    this.changed();
  }

  /** Every keyframe replaced by `keys`, one step to undo; none selected. */
  replace(keys) {
    this.history.record();
    this.path.keyframes = keys;
    this.selected = -1;
    this.changed();
  }

  remove(index) {
    this.history.record();
    this.path.keyframes.splice(index, 1);
    this.selected = -1;
    this.changed();
  }

  select(index) {
    this.selected = index;
    this.changed();
  }

  /** Typed or dragged values of keyframe `index`, one step to undo; the keys stay in time order. */
  change(index, fields) {
    const keys = this.path.keyframes;
    const key = keys[index];
    if (!key) return;
    const before = JSON.stringify(keys);
    Object.assign(key, fields);
    if (fields.paint === null) delete key.paint;
    if (key.fade === 0) delete key.fade;
    if (key.ease && key.ease.every((e) => e === 0)) delete key.ease;
    keys.sort((a, b) => a.t - b.t);
    if (this.selected >= 0) this.selected = keys.indexOf(key);
    if (JSON.stringify(keys) !== before) this.history.push(before); // the same values again: no step
    this.changed();
  }
}
