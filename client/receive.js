// @ts-check
// The server's messages (protocol.js: ServerMessage), one case a type. Frames come apart, each with its JPEG
// (connection.js: onFrame). An error names the message it answers (`answers`, `id`), so a refusal undoes
// exactly what it refused: a paint message's settings in the panel, a move in flight.

import * as walkCamera from "./camera.js";
import { MESSAGES } from "./messages.js";
import { owns } from "./link.js";

/**
 * The page's receiver of the server's messages.
 * @param {any} page  state, connection, collider, walk, view360, panel, objects, send, sendCamera, startScene(scene),
 *                    picked(msg), notice(text)
 * @returns {(msg: import("./protocol.js").ServerMessage) => void}
 */
export function receiver(page) {
  return (msg) => {
    switch (msg.type) {
      case "ready":
        return ready(page, msg);
      case "error":
        return refused(page, msg);
      case "picked":
        return page.picked(msg);
      case "moved":
        return moved(page, msg);
      default:
        return undefined; // frames are handed on with their JPEG, and the server sends nothing else
    }
  };
}

/** @param {any} page @param {import("./protocol.js").Ready} msg */
function ready(page, msg) {
  const { state } = page;
  page.connection.healthy();
  state.readies += 1;
  state.refine = msg.refine;
  const fresh = state.scene?.name !== msg.scene.name;
  state.scene = msg.scene;
  if (fresh) {
    page.startScene(msg.scene);
  } else {
    // a reconnection: the server starts afresh, so restore the camera and settings we had
    page.collider.flight = null; // its answer was lost with the connection
    state.lastCamera = walkCamera.toCamera(walkCamera.fromCamera(msg.scene.camera));
    if (page.view360.active) state.lastCamera = null; // the server starts from a flat view: send the panorama's
    page.sendCamera();
    // one field a message: a setting the server refuses does not take the others with it
    for (const [name, value] of Object.entries(state.paint)) page.send(MESSAGES.paint({ [name]: value }));
  }
  const animate = msg.scene.animated && state.animate;
  if (msg.temporal !== state.temporal || msg.animate !== animate) page.send(MESSAGES.mode(state.temporal, animate));
}

/** @param {any} page @param {import("./protocol.js").ErrorMessage} msg */
function refused(page, msg) {
  const { state } = page;
  if (msg.answers === "paint" && state.lastPaint) {
    // the server keeps its old settings when it refuses a paint message: so does the panel
    const { changes, before } = state.lastPaint;
    for (const name of Object.keys(changes)) {
      if (owns(before, name)) state.paint[name] = before[name];
      else delete state.paint[name];
    }
    state.lastPaint = null;
    page.panel.show(state.paint);
    page.objects.show(state.paint);
    page.notice(`Refused: ${msg.message}`);
    return;
  }
  if (msg.answers === "move") page.collider.lost(msg.id); // its answer will not come: the walk moves on
  page.notice(msg.message);
}

/** @param {any} page @param {import("./protocol.js").Moved} msg */
function moved(page, msg) {
  const eye = page.collider.answer(msg);
  if (eye && page.walk.walk) page.walk.walk = { ...page.walk.walk, eye };
}
