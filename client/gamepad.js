// @ts-check
// Gamepads, in the standard mapping of the Gamepad API (https://w3c.github.io/gamepad/#remapping): the left
// stick walks, the right stick looks, the triggers go down (left) and up (right), Y (button 3) resets the
// camera. A stick's travel inside the dead zone counts as none; beyond it, the travel is rescaled from 0, so a
// slight push walks slowly.

export const DEAD_ZONE = 0.15;
const RESET = 3; // Y on an Xbox pad, triangle on a PlayStation one
const TRIGGERS = [6, 7]; // left: down, right: up

/** A stick's (x, y) with the radial dead zone applied: length 0 inside it, rescaled to [0, 1] beyond. */
export function stick(x, y) {
  const length = Math.hypot(x, y);
  if (!(length > DEAD_ZONE)) return [0, 0]; // NaN from a broken pad: none
  const scale = Math.min(1, (length - DEAD_ZONE) / (1 - DEAD_ZONE)) / length;
  return [x * scale, y * scale];
}

const pressed = (button) => (typeof button === "object" ? Boolean(button?.pressed) : button === 1);
const value = (button) => (typeof button === "object" ? Number(button?.value) || 0 : Number(button) || 0);

/** The first connected pad of `navigator.getGamepads()`, or null. */
export function firstPad() {
  const pads = navigator.getGamepads?.() ?? [];
  for (const pad of pads) if (pad?.connected) return pad;
  return null;
}

/**
 * What a pad asks for: move [forward, right, up] and look [yaw, pitch] in -1..1, and whether the reset
 * button went down since `wasReset` (the last reading's).
 */
export function read(pad, wasReset) {
  const axes = pad.axes ?? [];
  const [lx, ly] = stick(axes[0] ?? 0, axes[1] ?? 0);
  const [rx, ry] = stick(axes[2] ?? 0, axes[3] ?? 0);
  const buttons = pad.buttons ?? [];
  const rise = value(buttons[TRIGGERS[1]]) - value(buttons[TRIGGERS[0]]);
  const reset = pressed(buttons[RESET]);
  return {
    move: [-ly, lx, Math.abs(rise) > DEAD_ZONE ? rise : 0], // stick up (y < 0) walks forward
    look: [rx, -ry],
    reset: reset && !wasReset,
    held: reset,
  };
}
