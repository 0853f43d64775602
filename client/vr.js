// @ts-check
// VR: the stereo panorama in a headset (WebXR `immersive-vr`). The button shows wherever the browser says it
// supports such a session. In the headset the client asks for stereo top-bottom equirect paintings (left eye
// on top, view360.js) and each eye's view samples its own half (panorama.js); the head turns at the
// headset's rate from that local panorama, with no message to the server. The thumbstick walks along the
// head's heading, level, and walking sends cameras as the keys do.
//
// The XR reference space `local` is tied to the panorama's frame when the session starts: its x to the
// panorama camera's right, y to its up, -z to its forward (the heading the walk had in the 360° view).

import { invert, multiply } from "./panorama.js";

const DEAD_ZONE = 0.15; // thumbstick travel that does not move (a resting stick is rarely at exactly 0)
const XR_TO_PANO = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1]; // -z forward -> +z forward

/** `v` (3) rotated by the unit quaternion `q` ({x, y, z, w}). */
function rotate(q, v) {
  const u = [q.x, q.y, q.z];
  const t = [0, 1, 2].map((k) => 2 * (u[(k + 1) % 3] * v[(k + 2) % 3] - u[(k + 2) % 3] * v[(k + 1) % 3])); // 2 u x v
  return [0, 1, 2].map((k) => v[k] + q.w * t[k] + (u[(k + 1) % 3] * t[(k + 2) % 3] - u[(k + 2) % 3] * t[(k + 1) % 3]));
}

/** A view's `panoFromClip`: its projection and head rotation undone (the panorama lies at infinity, so the
 * head's position does not count), then the reference space turned into the panorama's frame. */
export function eyeFromClip(view) {
  const rotation = [...view.transform.inverse.matrix];
  rotation[12] = rotation[13] = rotation[14] = 0;
  return multiply(XR_TO_PANO, invert(multiply([...view.projectionMatrix], rotation)));
}

/** WebXR, where the browser has it (not yet in TypeScript's DOM types). @returns {any} */
const xr = () => /** @type {any} */ (navigator).xr;

export class VrSession {
  /**
   * @param {HTMLButtonElement} button  "Enter VR": shown only where an immersive-vr session is supported
   * @param {import("./view360.js").View360} view360           the 360° view whose panorama and renderer the headset uses
   * @param {object} actions            enter(): the 360° view on (false if it cannot be); stereo(layout);
   *                                    advance(now): one frame's walking and sending; speed(): units a second;
   *                                    move(delta world vector); notice(text)
   */
  constructor(button, view360, actions) {
    this.button = button;
    this.view360 = view360;
    this.actions = actions;
    this.session = null;
    this.space = null;
    this.frames = 0; // headset frames drawn (the tests read these)
    this.views = []; // the eyes drawn in the last frame, with their viewports
    this.lastTime = null;
    this.capture = false; // set by a test: the next frame keeps a PNG of what it drew in `shot`
    this.shot = null;
    button.addEventListener("click", () => (this.session ? this.session.end() : this.start()));
    this.detect();
  }

  async detect() {
    try {
      this.button.hidden = !(await xr()?.isSessionSupported("immersive-vr"));
    } catch {
      this.button.hidden = true; // blocked by a permissions policy, say
    }
  }

  async start() {
    if (!this.actions.enter()) return;
    try {
      const session = await xr().requestSession("immersive-vr");
      const gl = /** @type {any} */ (this.view360.pano.gl); // WebXR's makeXRCompatible: not in TypeScript's DOM types
      await gl.makeXRCompatible();
      session.updateRenderState({ baseLayer: new (/** @type {any} */ (window).XRWebGLLayer)(session, gl) });
      this.space = await session.requestReferenceSpace("local");
      this.session = session;
      session.addEventListener("end", () => this.ended());
    } catch (error) {
      this.actions.notice(`VR could not start: ${error.message}`);
      return;
    }
    this.view360.presenting = true;
    this.button.textContent = "Exit VR";
    this.actions.stereo("top-bottom"); // each eye its own painting from now on
    this.session.requestAnimationFrame((time, frame) => this.onFrame(time, frame));
  }

  ended() {
    this.session = null;
    this.lastTime = null;
    this.view360.presenting = false;
    this.view360.shownKey = ""; // the flat view draws again
    this.button.textContent = "Enter VR";
    this.actions.stereo("mono");
  }

  onFrame(time, frame) {
    const session = frame.session;
    session.requestAnimationFrame((t, f) => this.onFrame(t, f));
    const pose = frame.getViewerPose(this.space);
    if (pose) this.thumbstick(pose, time);
    this.actions.advance(time);
    if (!pose) return;
    const layer = session.renderState.baseLayer;
    const pano = this.view360.pano;
    pano.gl.bindFramebuffer(pano.gl.FRAMEBUFFER, layer.framebuffer);
    this.views = pose.views.map((view) => {
      const { x, y, width, height } = layer.getViewport(view);
      pano.draw(eyeFromClip(view), [x, y, width, height], view.eye);
      return { eye: view.eye, viewport: [x, y, width, height] };
    });
    this.frames += 1;
    if (this.capture) {
      this.capture = false;
      this.shot = pano.canvas.toDataURL("image/png"); // in the frame that drew it: the buffer still holds it
    }
  }

  /** The thumbstick walks: forward and sideways along the head's level heading, at the walk's speed. */
  thumbstick(pose, time) {
    const dt = this.lastTime === null ? 0 : Math.min(0.1, (time - this.lastTime) / 1000);
    this.lastTime = time;
    let [side, ahead] = [0, 0];
    for (const source of this.session.inputSources) {
      const axes = source.gamepad?.axes ?? [];
      const [x, y] = axes.length >= 4 ? [axes[2], axes[3]] : [axes[0] ?? 0, axes[1] ?? 0]; // xr-standard: 2, 3
      if (Math.hypot(x, y) > DEAD_ZONE) [side, ahead] = [side + x, ahead - y]; // pushed away is -y
    }
    if (!dt || (!side && !ahead)) return;
    const q = pose.transform.orientation;
    const heading = this.level(rotate(q, [0, 0, -1]));
    const right = this.level(rotate(q, [1, 0, 0]));
    const step = this.actions.speed() * dt;
    this.actions.move([0, 1, 2].map((k) => (ahead * heading[k] + side * right[k]) * step));
  }

  /** A reference-space direction as a level unit vector in the world (zero when it points straight up). */
  level(v) {
    const world = this.view360.toWorld([v[0], v[1], -v[2]]);
    world[1] = 0;
    const length = Math.hypot(...world);
    return length > 1e-6 ? world.map((x) => x / length) : [0, 0, 0];
  }
}
