// @ts-check
// The rcp walk-through: wires the connection, the frames, the walk controls, the panel and the overlay. The
// page's state is state.js's, the server's messages are received in receive.js, Save is save.js and the
// address that always carries the view is share.js (written and read by link.js).
// Query parameters: ?scene=NAME, ?width=W&height=H (a fixed painting size instead of the window's; the
// Resolution setting scales either), ?quality=Q (JPEG quality), and the rest of the view (link.js). A server
// with a token (RCP_TOKEN) is opened as /#token=TOKEN (or ?token=TOKEN): the page takes it out of its address at
// once (keeping it for this tab only), so a link never carries it.
//
// `window.rcp` exposes the state, the messages sent and the overlay's numbers, for the tests.

import { CAMERA, CLIENT, ENGINE_DEFAULTS, PAINT } from "./protocol.js";
import { MESSAGES } from "./messages.js";
import * as walkCamera from "./camera.js";
import { Connection } from "./connection.js";
import { FrameView } from "./frames.js";
import { qualityControl } from "./upscale.js";
import { Overlay } from "./overlay.js";
import { objectsPanel } from "./objects.js";
import { paintPanel } from "./panel.js";
import { stylesPanel } from "./styles.js";
import { pathPanel } from "./path/panel.js";
import { WalkController } from "./walk.js";
import { Uploader } from "./upload.js";
import { View360, panoramaSize } from "./view360.js";
import { VrSession } from "./vr.js";
import { Collider } from "./collide.js";
import { PickMask } from "./pickmask.js";
import { decode as decodeLink, encode as encodeLink, linkNotice, takeToken } from "./link.js";
import { initialState, notifier } from "./state.js";
import { receiver } from "./receive.js";
import { save } from "./save.js";
import { addressKeeper, copyLink, pageOptions, shareLink } from "./share.js";
import { loadScenes, loadStyles } from "./lists.js";

/** @param {string} id @returns {any} */
const $ = (id) => document.getElementById(id);
// the token leaves the address before anything else reads it
const given = takeToken(location.href);
if (given.address !== location.pathname + location.search + location.hash) history.replaceState(null, "", given.address);
const token = given.token ?? sessionStorage.getItem("rcp.token");
if (token) sessionStorage.setItem("rcp.token", token); // a reload of this tab still has it; a copied address does not
const link = decodeLink(location.search); // the view this address carries (applied once its scene is ready)
const authorization = token ? { authorization: `Bearer ${token}` } : {};
const canvas = $("view");

const state = initialState(link);
const notice = notifier(state, $("toast"));
const sent = []; // the last 500 messages sent, for the tests

const overlay = new Overlay();
const frames = new FrameView(canvas, {
  shown: (meta) => overlay.frameShown(meta),
  failed: (text) => notice(text),
});
// the 360° view: equirect paintings of the walk's position, looked around in locally (view360.js)
const view360 = new View360($("pano"), {
  shown: (meta) => overlay.frameShown(meta),
  failed: (text) => notice(text),
});
const walk = new WalkController(canvas, {
  reset: resetCamera,
  togglePanel,
  notice,
  keyframe: () => path.add(),
});
const collider = new Collider(send);
walk.mover = collider;
const wsUrl = new URL("ws", location.href); // beside the page: works behind a proxy's path prefix too
wsUrl.protocol = wsUrl.protocol === "https:" ? "wss:" : "ws:";
if (token) wsUrl.searchParams.set("token", token); // a browser's WebSocket cannot send headers
const connection = new Connection(wsUrl.href, {
  onOpen: sendHello,
  onMessage: (msg) => receive(msg),
  onFrame: (meta, jpeg) => (view360.accepts(meta) ? view360 : frames).push(meta, jpeg),
  onState: (connectionState, detail) => overlay.connection(connectionState, detail),
});

// ---- sending ----

function send(msg) {
  if (!connection.send(msg)) return false;
  state.messages += 1;
  sent.push(msg);
  if (sent.length > 500) sent.shift();
  return true;
}

/** The camera the walk shows: its own view, or in the 360° view the panorama at its eye. */
function currentCamera() {
  return view360.active ? view360.camera(walk.walk) : walkCamera.toCamera(walk.walk);
}

function sendCamera() {
  const camera = currentCamera();
  if (walkCamera.sameCamera(camera, state.lastCamera)) return;
  state.cameraId += 1;
  if (send(MESSAGES.camera(camera, state.cameraId))) {
    overlay.cameraSent(state.cameraId);
    state.lastCamera = camera;
  }
}

function sendHello() {
  const [width, height] = state.size;
  send(MESSAGES.hello(state.sceneName, width, height, state.quality));
}

// ---- a scene starts (receive.js receives the server's messages) ----

function startScene(scene) {
  walk.place(scene.camera);
  if (view360.active) view360.enter(walk.walk); // the new scene's panorama faces its own camera's way
  showViewpoints(scene);
  state.lastCamera = walkCamera.toCamera(walk.walk); // what the server shows after hello
  state.paint = {};
  objects.setScene(scene.paint);
  objects.show(state.paint);
  state.defaults = { ...ENGINE_DEFAULTS, z0: Number(walk.walk.distance.toPrecision(3)), ...scene.paint };
  panel.setScene(state.defaults);
  stylesUi?.show(null);
  $("scene").value = scene.name;
  $("animate").disabled = !scene.animated;
  $("animate-row").classList.toggle("disabled", !scene.animated);
  $("scene-info").textContent = `${scene.triangles.toLocaleString()} triangles${scene.animated ? " · animated" : ""}`;
  document.title = `${scene.title} · rcp`;
  if (link.scene === scene.name) applyLink();
}

/** The view of the page's address, once, on its scene: camera, 360° view, switches and painting. */
function applyLink() {
  link.scene = null; // once: a later visit to this scene starts from its own view
  if (link.camera) walk.place(link.camera);
  if (link.switches.temporal !== undefined) state.temporal = $("temporal").checked = link.switches.temporal;
  if (link.switches.animate !== undefined) state.animate = $("animate").checked = link.switches.animate;
  if (Object.keys(link.paint).length) {
    applyPaint({ ...link.paint });
    stylesUi?.show(link.paint.style ?? null);
  }
  if (link.projection === "equirect" && toggle360(true)) {
    view360.yaw0 = link.heading ?? view360.yaw0;
    state.lastCamera = null;
  }
}

// ---- the painting's size ----

function wantedFlatSize() {
  const base = link.page.width !== undefined ? [link.page.width, link.page.height] : [innerWidth, innerHeight];
  return base.map((n) => Math.max(16, Math.min(4096, Math.round(n * state.resolution))));
}

function wantedSize() {
  const size = wantedFlatSize();
  return view360.active ? panoramaSize(...size) : size; // a panorama costs about what the flat view does
}

/** Size the canvas to the painting and tell the server; false when nothing changed. */
function applySize() {
  const size = wantedSize();
  if (size[0] === state.size[0] && size[1] === state.size[1]) return false;
  state.size = size;
  frames.resize(...size);
  path?.showSizes();
  if (state.scene) send(MESSAGES.view(size[0], size[1], state.quality));
  return true;
}

let resizeTimer = 0;
addEventListener("resize", () => {
  clearTimeout(resizeTimer);
  resizeTimer = setTimeout(applySize, 250);
});

// ---- the animation loop: move, send at most one camera a frame, refresh the overlay ----

let lastTick = performance.now();
let lastOverlay = 0;

function tick(now) {
  requestAnimationFrame(tick); // first: a frame's work that fails does not stop the walk
  advance(now);
}

/** One animation frame's work (a headset's frames call it too, vr.js). */
function advance(now) {
  const dt = Math.min(0.1, Math.max(0, now - lastTick) / 1000);
  walk.step(dt);
  keepInside();
  if (state.keyed && !walkCamera.sameCamera(currentCamera(), state.keyed.camera)) paintKeyed(null); // walked on
  lastTick = Math.max(lastTick, now);
  if (walk.walk && state.scene && connection.state === "open") {
    collider.flush(walk.walk.eye, dt);
    sendCamera();
  }
  flushPaint();
  view360.draw(walk.walk, state.size[1]);
  const local = vr.session ? "VR" : view360.active ? "360°" : null; // drawn here, at the display's rate
  overlay.viewDrawn(local, vr.session ? vr.frames : (view360.pano?.drawn ?? 0), now);
  if (now - lastOverlay > 200) {
    lastOverlay = now;
    overlay.update(now);
    overlay.walker(walk.pad, collider.enabled ? collider.body : null);
    $("hint").classList.toggle("away", walk.moved);
    updateAddress();
  }
}

/** The walk stays where the server paints (the camera schema's bounds), said once each time it gets there. */
function keepInside() {
  if (!walk.walk) return;
  const inside = walkCamera.keptInside(walk.walk);
  if (inside !== walk.walk) {
    walk.walk = inside;
    collider.pending = [0, 0, 0]; // moves further out would only be undone
    const limit = walkCamera.COORDINATE_LIMIT.toExponential().replace("+", "");
    if (!state.atBound) notice(`The walk stops at the edge of the space painted here, ±${limit} scene units`);
    state.atBound = true;
  } else if (state.atBound && walk.walk.eye.every((x) => Math.abs(x) < 0.9 * walkCamera.COORDINATE_LIMIT)) {
    state.atBound = false;
  }
}

// ---- the panel ----

let paintChanges = {}; // edits of this animation frame, sent together
let paintBefore = {}; // state.paint before this frame's edits
const panel = paintPanel($("paint"), (name, value) => {
  if (value === null) delete state.paint[name];
  else state.paint[name] = value;
  paintChanges[name] = value;
});

// ---- settings per object and material: a click on the view (a press without a drag) picks ----

const objects = objectsPanel($("objects"), (per, table) => {
  if (table === null) delete state.paint[per];
  else state.paint[per] = table;
  paintChanges[per] = table;
});
const pickMask = new PickMask($("pick"));

/** The answer to a click: the object lights up on the view, and the Objects section opens on it. */
function picked(msg) {
  objects.picked(msg);
  if (msg.mask) pickMask.show(msg.mask);
  if (msg.object === null) return;
  const section = $("objects-section");
  const open = () => {
    if ($("panel").classList.contains("collapsed")) togglePanel();
    section.scrollIntoView({ block: "start", behavior: "smooth" });
    section.classList.remove("flash");
    void section.offsetWidth; // restart the highlight's animation
    section.classList.add("flash");
  };
  // a collapsed panel (a phone's sheet) opens once the object has lit up, not over it
  if ($("panel").classList.contains("collapsed")) setTimeout(open, 700);
  else open();
}

let pressed = null; // where and when a press on the view began
canvas.addEventListener("pointerdown", (event) => {
  pressed = { x: event.clientX, y: event.clientY, at: performance.now() };
});
canvas.addEventListener("pointerup", (event) => {
  const click = pressed && Math.hypot(event.clientX - pressed.x, event.clientY - pressed.y) < 4;
  if (!click || performance.now() - pressed.at > 400 || !state.scene) return;
  const box = canvas.getBoundingClientRect();
  const [width, height] = state.size;
  const x = Math.min(width - 1, Math.max(0, Math.floor(((event.clientX - box.left) / box.width) * width)));
  const y = Math.min(height - 1, Math.max(0, Math.floor(((event.clientY - box.top) / box.height) * height)));
  send(MESSAGES.pick(x, y));
});

// ---- styles and presets ----

let stylesUi = null; // the Style section, once the styles are known

/** Replace the user's painting settings by `settings` (a style and what is changed beside it). */
function applyPaint(settings) {
  for (const name of Object.keys(state.paint)) if (!Object.hasOwn(settings, name)) paintChanges[name] = null;
  Object.assign(paintChanges, settings);
  state.paint = { ...settings };
  showPaint();
}

/** The panel shows the style's settings as the base, and the user's own changes over them. */
function showPaint() {
  const { style, ...changed } = state.paint;
  panel.setScene({ ...state.defaults, ...(state.styles[style]?.settings ?? {}) });
  panel.show(changed);
  objects.show(state.paint);
}

function flushPaint() {
  if (Object.keys(paintChanges).length && state.scene && send(MESSAGES.paint(paintChanges))) {
    state.lastPaint = { changes: paintChanges, before: paintBefore }; // undone if the server refuses it
  }
  paintChanges = {}; // not sent while disconnected: the reconnection restores state.paint
  paintBefore = { ...state.paint };
}

/**
 * The walk paints `table` (the camera path's painting at a scrubbed time, as the server names it: POST
 * /api/paths) in place of the page's own settings of those names, at the view it stands at now, until it moves
 * on; null: the page's own settings again. Sent with this frame's edits; state.paint stays the page's own.
 * @param {Object<string, any> | null} table
 */
function paintKeyed(table) {
  const names = new Set([...Object.keys(state.keyed?.paint ?? {}), ...Object.keys(table ?? {})]);
  for (const name of names) {
    paintChanges[name] = table && Object.hasOwn(table, name) ? table[name] : (state.paint[name] ?? null);
  }
  state.keyed = table ? { paint: { ...table }, camera: currentCamera() } : null;
}

function resetCamera() {
  if (state.scene) walk.place(state.scene.camera);
  $("viewpoint").value = "";
}

// the cameras a model's file brings besides the scene's own (SceneInfo.viewpoints): one select, hidden
// when there are none
function showViewpoints(scene) {
  const select = $("viewpoint");
  select.replaceChildren(new Option("the scene's camera", ""));
  for (const [index, viewpoint] of scene.viewpoints.entries()) select.append(new Option(viewpoint.name, String(index)));
  $("viewpoint-row").hidden = scene.viewpoints.length === 0;
}

function goToViewpoint() {
  const index = $("viewpoint").value;
  if (!state.scene) return;
  walk.place(index === "" ? state.scene.camera : state.scene.viewpoints[Number(index)].camera);
}

function togglePanel() {
  const collapsed = $("panel").classList.toggle("collapsed");
  $("panel-toggle").setAttribute("aria-expanded", String(!collapsed));
}

function switchScene(name) {
  state.sceneName = name;
  state.scene = null; // the `ready` that follows starts the scene afresh
  const url = new URL(location.href);
  url.search = encodeLink({ scene: name, page: pageOptions(page) });
  history.replaceState(null, "", url);
  sendHello();
}

$("panel-toggle").addEventListener("click", togglePanel);
$("o-retry").addEventListener("click", () => connection.start());
$("scene").addEventListener("change", (event) => {
  event.target.blur(); // keys walk again
  switchScene(event.target.value);
});
$("reset-camera").addEventListener("click", resetCamera);
$("viewpoint").addEventListener("change", goToViewpoint);
$("reset-paint").addEventListener("click", () => {
  for (const name of Object.keys(state.paint)) paintChanges[name] = null; // sent with this frame's edits
  state.paint = {};
  showPaint();
  stylesUi?.show(null);
});
$("temporal").addEventListener("change", (event) => {
  state.temporal = event.target.checked;
  send(MESSAGES.mode(state.temporal, undefined));
});
$("animate").addEventListener("change", (event) => {
  state.animate = event.target.checked;
  send(MESSAGES.mode(undefined, state.animate));
});
$("quality").addEventListener("input", (event) => {
  state.quality = Number(event.target.value);
  $("quality-value").textContent = state.quality;
});
$("quality").addEventListener("change", () => send(MESSAGES.view(undefined, undefined, state.quality)));
$("resolution").addEventListener("change", (event) => {
  event.target.blur();
  state.resolution = Number(event.target.value);
  applySize();
});
$("save").addEventListener("click", () => save(page, $("save")));
$("copy-link").addEventListener("click", (event) => {
  event.target.blur();
  copyLink(page, $("copy-link"), $("link-box"));
});
$("collide").addEventListener("change", (event) => {
  event.target.blur();
  state.collide = collider.enabled = event.target.checked;
  collider.reset();
});
$("gravity").addEventListener("change", (event) => {
  event.target.blur();
  state.gravity = collider.gravity = event.target.checked;
});
$("view360").addEventListener("click", (event) => {
  event.target.blur(); // keys walk again
  toggle360(!view360.active);
});

// ---- the 360° view: the flat view's size and camera are swapped for the panorama's ----

/** Turn the 360° view on or off; false when this browser cannot show it. */
function toggle360(on) {
  if (on === view360.active) return true;
  if (on && !view360.available()) {
    notice(`the 360° view needs WebGL2: ${view360.problem}`);
    return false;
  }
  state.lastCamera = null; // the camera changes kind: send it even where it stands still
  if (on) {
    view360.enter(walk.walk);
    applySize(); // the panorama's size first, so the server never pairs an equirect camera with a flat size
    sendCamera();
  } else {
    view360.leave();
    sendCamera();
    applySize();
  }
  $("view360").setAttribute("aria-pressed", String(on));
  return true;
}

// ---- start: the scene list (lists.js), then the walk-through ----

async function start() {
  if (matchMedia("(max-width: 700px)").matches) togglePanel();
  collider.enabled = $("collide").checked = state.collide;
  collider.gravity = $("gravity").checked = state.gravity;
  $("resolution").value = String(state.resolution);
  if (matchMedia("(pointer: coarse)").matches) $("hint").textContent = "One finger looks · two move · the stick walks";
  $("quality").value = state.quality;
  $("quality-value").textContent = state.quality;
  applySize();
  state.scenes = await loadScenes(authorization, (text) => ($("o-connection").textContent = text), notice);
  if (state.scenes === null) return; // refused: retrying cannot help
  const names = state.scenes.map((s) => s.name);
  for (const scene of state.scenes) $("scene").append(new Option(`${scene.title} (${scene.name})`, scene.name));
  names.push(...(await uploads.restore())); // this browser's uploads the server still has
  if (state.sceneName && !names.includes(state.sceneName) && state.sceneName.startsWith("u-")) {
    const shared = await fetch(`api/scenes/${encodeURIComponent(state.sceneName)}`, { headers: authorization }).catch(() => null);
    if (shared?.ok) {
      const info = await shared.json(); // someone's upload, shared by its link
      $("scene").append(new Option(`${info.title} (shared)`, info.name));
      names.push(info.name);
    }
  }
  if (!names.includes(state.sceneName)) {
    const wanted = state.sceneName;
    state.sceneName = names.includes("default") ? "default" : names[0];
    link.scene = wanted ? null : state.sceneName; // a view of another scene does not fit this one
    if (wanted?.startsWith("u-")) notice(`The uploaded scene of this link has expired; showing the ${state.sceneName} scene`);
    else if (wanted) notice(`no scene '${wanted}' here; showing another`);
  }
  const problems = [...link.pageProblems, ...(link.scene ? link.problems : [])];
  if (problems.length) notice(linkNotice(problems)); // one notice for all of them
  if (!state.sceneName) return notice("the server has no scenes");
  const styles = await loadStyles(authorization);
  state.styles = Object.fromEntries(styles.map((s) => [s.name, s]));
  stylesUi = stylesPanel(styles, { current: () => state.paint, apply: applyPaint, notice });
  connection.start();
  requestAnimationFrame(tick);
}

const uploads = new Uploader($("scene"), authorization, { chosen: switchScene, notice });

qualityControl($("walk-quality"), (quality) => {
  frames.upscaler.quality = quality;
  frames.draw();
});

// ---- the camera path: keyframes from the walk, played back, rendered into a video ----

const path = pathPanel($("path"), {
  camera: currentCamera,
  place: (camera) => walk.place(camera),
  keyed: paintKeyed,
  scene: () => state.scene,
  request: () => {
    const paint = MESSAGES.paint({ ...state.paint });
    delete paint.type;
    return { paint, width: state.size[0], height: state.size[1] };
  },
  /** The view's painting size, as a flat film or a 360° one would take it. */
  viewSize: (film) => {
    const flat = view360.active ? wantedFlatSize() : state.size;
    return film === "equirect" ? panoramaSize(...flat) : flat;
  },
  authorization,
  notice,
});
// a film's Cancel counts once a job: a second click while the first is answered would cancel it again, and the
// panel would finish the job twice
let cancelledJob = null;
$("path")
  .querySelector('[data-path="cancel"]')
  .addEventListener(
    "click",
    (event) => {
      if (path.job !== null && path.job === cancelledJob) event.stopImmediatePropagation();
      cancelledJob = path.job;
    },
    { capture: true },
  );

// ---- VR: the stereo panorama in a headset, where the browser has one (vr.js) ----

const vr = new VrSession($("enter-vr"), view360, {
  enter: () => toggle360(true),
  stereo: (layout) => {
    view360.stereo = layout;
    state.lastCamera = null;
    sendCamera();
  },
  advance,
  speed: () => walk.speed,
  move: (delta) => {
    if (collider.active) collider.push(delta); // the headset walks, not flies, too
    else walk.walk = { ...walk.walk, eye: walk.walk.eye.map((x, k) => x + delta[k]) };
  },
  notice,
});

// ---- what the other modules are given: the page's parts, and what they may ask of it ----

const page = {
  state, link, authorization, connection, collider, walk, view360, panel, objects, overlay,
  send, sendCamera, currentCamera, startScene, picked, notice,
};
const receive = receiver(page);
const updateAddress = addressKeeper(page);

/** @type {any} */ (window).rcp = {
  state, sent, overlay, walk, connection, frames, panel, objects, path, canvas, uploads, view360, vr, collider, pickMask,
  shareLink: () => shareLink(page),
  MESSAGES,
  PROTOCOL: { client: CLIENT, paint: PAINT, camera: CAMERA },
  ENGINE_DEFAULTS,
};
start();
