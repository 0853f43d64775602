// @ts-check
// Walk-through input: keys, mouse, wheel and touch move a walk camera (camera.js), stepped once an
// animation frame. Keys are physical (`event.code`), so WASD sits under the same fingers on any layout.
//
//   W A S D  move (forward along the view, sideways)    Q E  down, up (world y)    Shift  faster
//   drag, or a locked pointer (L, double-click)  look   arrows  turn              wheel  fov, Shift+wheel speed
//   touch: one finger looks, two fingers move           R  reset the camera        P  the panel   K  a keyframe
//   gamepad: left stick walks, right stick looks, triggers down and up, Y resets (gamepad.js)
//
// With a `mover` (collide.js) active, moves go through it (to be kept clear of surfaces) instead of moving the
// eye here, and forward is level: a walker does not walk into the floor by looking down.

import * as walkCamera from "./camera.js";
import * as gamepad from "./gamepad.js";

const LOOK_PER_PIXEL = 0.0032; // radians per mouse pixel at 60 degrees fov; scaled with fov (zoomed in turns slower)
const TURN_RATE = [1.6, 1.1]; // arrow keys: yaw, pitch in radians per second
const FAST = 4; // Shift multiplies the walking speed
const EASE = 14; // 1/s: how fast the walking speed follows the keys (smooth starts and stops)
const MOVES = { KeyW: [1, 0, 0], KeyS: [-1, 0, 0], KeyD: [0, 1, 0], KeyA: [0, -1, 0], KeyE: [0, 0, 1], KeyQ: [0, 0, -1] };
const TURNS = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, 1], ArrowDown: [0, -1] };

/** Keys a focused control needs for itself: typing into boxes, arrows on sliders. Other keys still walk. */
function forControl(event) {
  const target = event.target;
  if (target.matches?.("textarea, select, input[type=number], input[type=text]")) return true;
  return target.matches?.("input[type=range]") && event.code.startsWith("Arrow");
}

export class WalkController {
  /**
   * @param {HTMLCanvasElement} canvas  receives the pointer, wheel and touch input
   * @param {object} actions            reset(), togglePanel(), notice(text, kind)
   */
  constructor(canvas, actions) {
    this.canvas = canvas;
    this.actions = actions;
    this.walk = null; // camera.js walk camera: eye, yaw, pitch, fov, distance
    this.speed = 1; // scene units per second
    this.velocity = [0, 0, 0]; // forward, right, up: scene units per second
    this.moved = false; // the user has moved since the page opened
    this.held = new Set();
    this.touches = new Map(); // pointer id -> last position
    this.dragging = false;
    this.mover = null; // collide.js: {active, push(world delta)}
    this.pad = null; // the id of the gamepad in use, null when none
    this.padReset = false; // the reset button was down at the last reading
    this.stickAt = [0, 0]; // the on-screen stick (touch screens): x right, y down, length up to 1
    this.listen();
    this.listenStick(document.getElementById("stick"));
  }

  /** The on-screen stick of a touch screen: held and pushed, it walks as a gamepad's left stick does. */
  listenStick(stick) {
    if (!stick) return;
    const knob = stick.firstElementChild;
    let pointer = null;
    const follow = (event) => {
      const box = stick.getBoundingClientRect();
      const half = box.width / 2;
      let [x, y] = [(event.clientX - box.left - half) / half, (event.clientY - box.top - half) / half];
      const length = Math.hypot(x, y);
      if (length > 1) [x, y] = [x / length, y / length];
      this.stickAt = [x, y];
      knob.style.transform = `translate(${x * half * 0.55}px, ${y * half * 0.55}px)`;
      this.moved = true;
    };
    stick.addEventListener("pointerdown", (event) => {
      pointer = event.pointerId;
      stick.setPointerCapture(pointer);
      follow(event);
    });
    stick.addEventListener("pointermove", (event) => event.pointerId === pointer && follow(event));
    const release = (event) => {
      if (event.pointerId !== pointer) return;
      pointer = null;
      this.stickAt = [0, 0];
      knob.style.transform = "";
    };
    stick.addEventListener("pointerup", release);
    stick.addEventListener("pointercancel", release);
  }

  /** Move by `amount` = [forward, right, up] scene units: through the mover when one is active. */
  go(amount) {
    if (this.mover?.active) this.mover.push(walkCamera.displacement(this.walk, amount, true));
    else this.walk = walkCamera.moved(this.walk, amount);
  }

  /** Start from a protocol camera ({eye, look_at, up, fov}); the speed fits the scene's look distance. */
  place(camera) {
    this.walk = walkCamera.fromCamera(camera);
    this.speed = Math.min(50, Math.max(0.5, this.walk.distance * 0.15));
    this.velocity = [0, 0, 0];
    this.mover?.reset(); // a move in flight started from elsewhere
  }

  /** Advance by `dt` seconds: ease the velocity towards the held keys, move, turn. */
  step(dt) {
    if (!this.walk) return;
    const target = [0, 0, 0];
    for (const code of this.held) MOVES[code]?.forEach((v, k) => (target[k] += v));
    const [sx, sy] = gamepad.stick(...this.stickAt);
    target[0] -= sy;
    target[1] += sx;
    const pad = gamepad.firstPad();
    this.pad = pad ? pad.id || "gamepad" : null;
    let padLook = [0, 0];
    if (pad) {
      const input = gamepad.read(pad, this.padReset);
      this.padReset = input.held;
      if (input.reset) this.actions.reset();
      input.move.forEach((v, k) => (target[k] += v));
      padLook = input.look;
      if (input.move.some((v) => v !== 0) || padLook.some((v) => v !== 0)) this.moved = true;
    }
    const speed = this.speed * (this.held.has("ShiftLeft") || this.held.has("ShiftRight") ? FAST : 1);
    const ease = 1 - Math.exp(-EASE * dt);
    this.velocity = this.velocity.map((v, k) => {
      const next = v + (target[k] * speed - v) * ease;
      return target[k] === 0 && Math.abs(next) < 0.02 * this.speed ? 0 : next; // come to a full stop
    });
    if (this.velocity.some((v) => v !== 0)) this.go(this.velocity.map((v) => v * dt));
    let [yaw, pitch] = padLook;
    for (const code of this.held) {
      const turn = TURNS[code];
      if (turn) [yaw, pitch] = [yaw + turn[0], pitch + turn[1]];
    }
    if (yaw || pitch) {
      const k = this.walk.fov / 60;
      this.walk = walkCamera.turned(this.walk, yaw * TURN_RATE[0] * k * dt, pitch * TURN_RATE[1] * k * dt);
    }
  }

  look(dx, dy) {
    if (!this.walk) return;
    const k = LOOK_PER_PIXEL * (this.walk.fov / 60);
    this.walk = walkCamera.turned(this.walk, dx * k, -dy * k);
    this.moved = true;
  }

  lockPointer() {
    const request = this.canvas.requestPointerLock?.();
    request?.catch?.(() => this.actions.notice("the browser refused to lock the mouse pointer", "error"));
  }

  // ---- the listeners ----

  listen() {
    const canvas = this.canvas;
    addEventListener("keydown", (event) => this.keyDown(event));
    addEventListener("keyup", (event) => this.held.delete(event.code));
    addEventListener("blur", () => this.held.clear());
    canvas.addEventListener("pointerdown", (event) => {
      canvas.focus();
      if (event.pointerType === "touch") this.touches.set(event.pointerId, [event.clientX, event.clientY]);
      else this.dragging = true;
      canvas.setPointerCapture(event.pointerId);
    });
    canvas.addEventListener("pointermove", (event) => {
      if (event.pointerType === "touch") this.touchMoved(event);
      else if (this.dragging || document.pointerLockElement === canvas) this.look(event.movementX, event.movementY);
    });
    const up = (event) => {
      this.touches.delete(event.pointerId);
      if (event.pointerType !== "touch") this.dragging = false;
    };
    canvas.addEventListener("pointerup", up);
    canvas.addEventListener("pointercancel", up);
    canvas.addEventListener("dblclick", () => this.lockPointer());
    canvas.addEventListener("contextmenu", (event) => event.preventDefault());
    canvas.addEventListener("wheel", (event) => this.wheel(event), { passive: false });
  }

  keyDown(event) {
    if (forControl(event) || event.ctrlKey || event.metaKey || event.altKey) return;
    const code = event.code;
    if (code === "KeyR") this.actions.reset();
    else if (code === "KeyL") this.lockPointer();
    else if (code === "KeyP") this.actions.togglePanel();
    else if (code === "KeyK" && !event.repeat) this.actions.keyframe?.(); // a keyframe of the camera path here
    else if (!MOVES[code] && !TURNS[code] && !code.startsWith("Shift")) return;
    this.held.add(code);
    this.moved = true;
    event.preventDefault();
  }

  touchMoved(event) {
    const last = this.touches.get(event.pointerId);
    if (!last || !this.walk) return;
    const [dx, dy] = [event.clientX - last[0], event.clientY - last[1]];
    this.touches.set(event.pointerId, [event.clientX, event.clientY]);
    if (this.touches.size === 1) {
      this.look(-dx, -dy); // one finger drags the world: the view turns the other way
    } else if (this.touches.size === 2) {
      // two fingers: each finger's move counts half, so the pair moves the camera by their mean motion
      const step = (this.speed / 150) * 0.5;
      this.go([-dy * step, -dx * step, 0]);
      this.moved = true;
    }
  }

  wheel(event) {
    if (!this.walk) return;
    event.preventDefault();
    const delta = event.deltaY || event.deltaX; // Shift+wheel scrolls sideways in some browsers
    if (event.shiftKey) {
      this.speed = Math.min(500, Math.max(0.01, this.speed * Math.exp(-delta * 0.002)));
      this.actions.notice(`walking speed ${this.speed.toPrecision(2)} units/s`, "info");
    } else {
      const [low, high] = walkCamera.FOV_RANGE;
      this.walk = { ...this.walk, fov: Math.min(high, Math.max(low, this.walk.fov * Math.exp(delta * 0.001))) };
    }
    this.moved = true;
  }
}
