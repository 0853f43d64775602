// @ts-check
// The 360° view mode: the client asks for equirect paintings of the walk's position and looks around in the
// newest one locally (panorama.js), at the display's rate, with no message to the server.
//
// The panorama's camera is the walk's eye with a level view along `yaw0`, the walk's heading when the mode
// was entered; looking around (drag, arrows, wheel) changes only the walk's yaw, pitch and fov, which the
// panorama's camera leaves out, so the camera sent stays the same and nothing is sent. Walking moves the eye:
// a new camera, and the server paints the panorama again (smaller while moving, refined at rest, as ever).
// A frame names its projection and stereo layout (mono, or top-bottom for a headset, vr.js): a panorama is
// shown here, in its layout.

import { decodeFrame } from "./bands.js";
import * as walkCamera from "./camera.js";
import { PanoramaView, dot } from "./panorama.js";

export const PANORAMA_FOV = 60; // the fov sent with a panorama: equirect ignores it; fixed, so zooming sends nothing
// A headset's pair: the right eye smudges as the left one where both see the same point, so the two eyes do not
// fight (`rcp bench projection --width 508` on the village: 1.8% of pixels in rivalry instead of 4.5%).
const PAIR_EYES = "shared";
const DETAIL_MARGIN = 1.5; // screen pixels drawn per panorama pixel in view, at most: more shows nothing new

/** The painting size (one eye's) of a panorama costing about as much as a `width` x `height` view: 2H x H,
 * H even (a video of it needs even sizes). */
export function panoramaSize(width, height) {
  const rows = 2 * Math.max(4, Math.min(1024, Math.round(Math.sqrt((width * height) / 2) / 2)));
  return [2 * rows, rows];
}

export class View360 {
  /**
   * @param {HTMLCanvasElement} canvas  the WebGL canvas, shown over the flat view while the mode is on
   * @param {object} handlers           shown(meta) after a panorama is uploaded, failed(message)
   */
  constructor(canvas, handlers) {
    this.canvas = canvas;
    this.handlers = handlers;
    this.pano = null; // PanoramaView, made on first use
    this.problem = null; // why the browser cannot show it (no WebGL2)
    this.active = false;
    this.presenting = false; // a headset draws the panorama (vr.js): the flat view waits
    this.stereo = "mono"; // "top-bottom" while a headset shows it
    this.yaw0 = 0; // the panorama camera's heading (radians, camera.js convention)
    this.newest = null; // {meta, jpeg} not yet decoded
    this.decoding = false;
    this.shownKey = ""; // what the canvas shows, to draw only when the view or the panorama changed
  }

  /** Whether this browser can show the 360° view (makes the WebGL2 renderer the first time). */
  available() {
    if (this.pano || this.problem) return this.pano !== null;
    try {
      this.pano = new PanoramaView(this.canvas);
    } catch (error) {
      this.problem = error.message;
    }
    return this.pano !== null;
  }

  enter(walk) {
    this.active = true;
    this.yaw0 = walk.yaw;
    this.shownKey = "";
    this.canvas.hidden = false;
  }

  leave() {
    this.active = false;
    this.canvas.hidden = true;
  }

  /** The panorama's frame (r0, u0, f0) in world coordinates. */
  frame() {
    const level = { yaw: this.yaw0, pitch: 0 };
    return [walkCamera.right(level), walkCamera.UP, walkCamera.forward(level)];
  }

  /** World vector -> the panorama's frame (x along r0, y along u0, z along f0). */
  toPano(v) {
    return this.frame().map((axis) => dot(v, axis));
  }

  /** Panorama frame -> world vector. */
  toWorld(v) {
    const [r, u, f] = this.frame();
    return [0, 1, 2].map((k) => v[0] * r[k] + v[1] * u[k] + v[2] * f[k]);
  }

  /** The protocol camera of the panorama at the walk's eye. */
  camera(walk) {
    const level = walkCamera.toCamera({ ...walk, yaw: this.yaw0, pitch: 0, fov: PANORAMA_FOV });
    const pair = this.stereo === "mono" ? {} : { eyes: PAIR_EYES };
    return { ...level, projection: "equirect", stereo: this.stereo, ...pair };
  }

  /** Whether the frame `meta` describes is a panorama (shown here, not in the flat view). */
  accepts(meta) {
    return meta.projection === "equirect";
  }

  /** A panorama arrived: decode the newest only (one arriving meanwhile replaces any still waiting). */
  push(meta, jpeg) {
    this.newest = { meta, jpeg };
    if (!this.decoding) this.decodeNewest();
  }

  async decodeNewest() {
    this.decoding = true;
    while (this.newest) {
      const { meta, jpeg } = this.newest;
      this.newest = null;
      try {
        const bitmap = await decodeFrame(meta, jpeg); // one JPEG, or its bands drawn in place (bands.js)
        this.pano.show(bitmap, meta.stereo);
        bitmap.close();
        this.handlers.shown(meta);
      } catch (error) {
        this.handlers.failed(`a panorama could not be shown: ${error.message}`);
      }
    }
    this.decoding = false;
  }

  /**
   * The share of the screen's resolution worth drawing: a panorama `rows` high has rows / pi pixels a radian,
   * the screen H / (2 tan(fov / 2)) at its centre; past DETAIL_MARGIN screen pixels a panorama pixel the
   * view only grows costlier (a software renderer's frame rate falls with every pixel), not sharper.
   */
  detail(walk, rows) {
    const screen = (this.canvas.clientHeight * Math.min(devicePixelRatio || 1, 2)) / (2 * Math.tan((walk.fov * Math.PI) / 360));
    const share = (DETAIL_MARGIN * rows) / Math.PI / screen;
    return Math.min(1, Math.max(0.25, Math.ceil(share * 8) / 8)); // in eighths: zooming reallocates rarely
  }

  /** Draw the walk's view of a panorama `rows` high when it changed (called once an animation frame). */
  draw(walk, rows) {
    if (!this.active || this.presenting || !walk) return;
    const resized = this.pano.fit(this.detail(walk, rows));
    const key = `${walk.yaw} ${walk.pitch} ${walk.fov} ${this.pano.uploaded} ${this.yaw0}`;
    if (key === this.shownKey && !resized) return;
    this.shownKey = key;
    const r = walkCamera.right(walk);
    const f = walkCamera.forward(walk);
    const u = [r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]]; // u = r x f
    this.pano.drawFlat(this.toPano(f), this.toPano(r), this.toPano(u), walk.fov);
  }

  /** The canvas as drawn now, as a PNG data URL (drawn again first: a WebGL canvas keeps no old frame). */
  snapshot(walk, rows) {
    this.shownKey = "";
    this.draw(walk, rows);
    return this.canvas.toDataURL("image/png");
  }
}
