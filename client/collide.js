// @ts-check
// Walking, not flying: with `collide` on, the walk's moves go to the server (`move`), which keeps the eye a
// body's radius from every surface, slides it along walls and walks it up stairs (rcp_server/engine/collide.py),
// and answers `moved` with where the eye ends. One move is in flight at a time: the moves made meanwhile add up
// and go next, so the walk is at most one round trip behind the keys. Gravity is a downward move, made while
// the server says the body is not standing.

import { MESSAGES } from "./messages.js";

const FALL = 3; // eye heights a second: how fast a walker falls with gravity on

export class Collider {
  /** @param {function} send  sends a message; false when the connection is down */
  constructor(send) {
    this.send = send;
    this.enabled = true;
    this.gravity = false;
    this.pending = [0, 0, 0]; // world units, not yet sent
    this.flight = null; // the id of the move in flight
    this.ids = 0;
    this.body = null; // the last `moved`: {radius, height, standing}
    this.answered = 0; // moves answered (the tests watch it)
  }

  /** Whether the walk's moves go through the server now. */
  get active() {
    return this.enabled;
  }

  /** The walk jumped (a reset, a viewpoint, a path, another scene): what was in flight no longer applies. */
  reset() {
    this.pending = [0, 0, 0];
    this.flight = null;
    this.body = null;
  }

  push(delta) {
    this.pending = this.pending.map((x, k) => x + delta[k]);
  }

  /** Once an animation frame: gravity, then the moves made since the last answer, if none is in flight. */
  flush(eye, dt) {
    if (!this.enabled || this.flight !== null) return;
    if (this.gravity && this.body?.height && !this.body.standing) this.pending[1] -= FALL * this.body.height * dt;
    const still = this.pending.every((x) => x === 0);
    if (still && this.body) return; // nothing to move; the first move (even a still one) measures the body
    const id = ++this.ids;
    const delta = this.pending.map((x) => Math.round(x * 1e6) / 1e6);
    if (this.send(MESSAGES.move(id, eye, delta, this.body?.height ?? null))) {
      this.flight = id;
      this.pending = [0, 0, 0];
    }
  }

  /** The server refused move `id`: no answer will come, so the next moves go. */
  lost(id) {
    if (id === this.flight) this.flight = null;
  }

  /** The server's answer: the eye to walk on from, or null when it answers a move that no longer applies. */
  answer(msg) {
    if (msg.id !== this.flight) return null;
    this.flight = null;
    this.answered += 1;
    this.body = { radius: msg.radius, height: msg.height, standing: msg.standing };
    return msg.eye;
  }
}
