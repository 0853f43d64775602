// @ts-check
// The walk-through camera: a position, yaw and pitch, with world +y up (shared/MISSION.md conventions:
// right-handed, y up, `fov` the vertical field of view in degrees).
//
// yaw 0 looks down -z, positive yaw turns right (towards +x); pitch is up from the horizon. In that frame
//   forward f = (sin(yaw) cos(pitch), sin(pitch), -cos(yaw) cos(pitch)),  right r = f x up = (cos(yaw), 0, sin(yaw)).
// The camera sent keeps `look_at` at the scene's own look distance ahead of the eye, so a focus depth
// `z0` left at its default (the eye-to-look_at distance) stays the same while walking.

import { CAMERA } from "./protocol.js";

export const UP = [0, 1, 0];
/** How far from the origin a camera's points may lie, per coordinate: the server's bound (protocol.js). */
export const COORDINATE_LIMIT = Math.min(...CAMERA.properties.eye.prefixItems.map((item) => item.maximum));
const PITCH_LIMIT = (89 * Math.PI) / 180; // looking straight up or down would make f parallel to up
export const FOV_RANGE = [10, 120];

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const length = (a) => Math.hypot(a[0], a[1], a[2]);

/** A walk camera from a protocol camera ({eye, look_at, up, fov}): yaw and pitch from its view direction. */
export function fromCamera({ eye, look_at, fov = 60 }) {
  const d = sub(look_at, eye);
  const distance = length(d) || 1;
  const f = d.map((x) => x / distance);
  return {
    eye: [...eye],
    yaw: Math.atan2(f[0], -f[2]),
    pitch: clampPitch(Math.asin(Math.max(-1, Math.min(1, f[1])))),
    fov,
    distance,
  };
}

export function clampPitch(pitch) {
  return Math.max(-PITCH_LIMIT, Math.min(PITCH_LIMIT, pitch));
}

export function forward({ yaw, pitch }) {
  return [Math.sin(yaw) * Math.cos(pitch), Math.sin(pitch), -Math.cos(yaw) * Math.cos(pitch)];
}

export function right({ yaw }) {
  return [Math.cos(yaw), 0, Math.sin(yaw)];
}

/** The world vector of a move by `amount` (scene units) = [forward, right, up]; `level`: forward along the
 * heading only (a walker does not walk into the floor by looking down). */
export function displacement(walk, [ahead, side, rise], level = false) {
  const f = forward(level ? { yaw: walk.yaw, pitch: 0 } : walk);
  const r = right(walk);
  return [0, 1, 2].map((k) => ahead * f[k] + side * r[k] + rise * UP[k]);
}

/** Move by `amount` (scene units) along forward, right and world up: amount = [forward, right, up]. */
export function moved(walk, amount) {
  const delta = displacement(walk, amount);
  return { ...walk, eye: walk.eye.map((x, k) => x + delta[k]) };
}

/** Turn by yaw and pitch deltas, in radians. */
export function turned(walk, dyaw, dpitch) {
  return { ...walk, yaw: walk.yaw + dyaw, pitch: clampPitch(walk.pitch + dpitch) };
}

const round = (x) => Math.round(x * 1e5) / 1e5; // 10 micro-units: shorter messages, no visible change

/** The protocol camera ({eye, look_at, up, fov}) this walk camera shows. */
export function toCamera(walk) {
  const f = forward(walk);
  const eye = walk.eye.map(round);
  return {
    eye,
    look_at: walk.eye.map((x, k) => round(x + walk.distance * f[k])),
    up: [...UP],
    fov: round(walk.fov),
  };
}

export function sameCamera(a, b) {
  if (!a || !b) return false;
  return a.fov === b.fov && [0, 1, 2].every((k) => a.eye[k] === b.eye[k] && a.look_at[k] === b.look_at[k]);
}

/**
 * The walk kept inside the space the server paints: the eye, and the look_at the scene's look distance ahead
 * of it, within COORDINATE_LIMIT on every axis. Returns the walk itself when it is inside.
 */
export function keptInside(walk) {
  const bound = COORDINATE_LIMIT - walk.distance;
  if (walk.eye.every((x) => Math.abs(x) <= bound)) return walk;
  return { ...walk, eye: walk.eye.map((x) => Math.max(-bound, Math.min(bound, x))) };
}
