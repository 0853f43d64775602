// The rcp walk-through: a canvas showing the painting streamed over /ws, walk-through controls, a settings
// panel and an overlay of live numbers. Query parameters: ?scene=NAME, ?width=W&height=H (a fixed painting
// size instead of the window's; the Resolution setting scales either), ?quality=Q (JPEG quality).
//
// `window.rcp` exposes the state, the messages sent and the frame statistics, for the tests.

import { PROTOCOL } from "./protocol.js";
import { MESSAGES } from "./messages.js";
import * as walkCamera from "./camera.js";
import { Connection } from "./connection.js";
import { ENGINE_DEFAULTS, paintPanel } from "./panel.js";

const $ = (id) => document.getElementById(id);
const query = new URLSearchParams(location.search);
const canvas = $("view");
const context = canvas.getContext("2d", { alpha: false });

const LOOK_PER_PIXEL = 0.0032; // radians per mouse pixel at 60 degrees fov (scaled with fov: zooming in turns slower)
const TURN_RATE = [1.6, 1.1]; // arrow keys: yaw, pitch in radians per second
const FAST = 4; // Shift multiplies the walking speed
const EASE = 14; // 1/s: how fast walking speed follows the keys (smooth starts and stops)
const LATENCY_SAMPLES = 31;

const state = {
  scenes: [], // SceneInfo of every scene (GET /api/scenes)
  sceneName: query.get("scene"),
  scene: null, // SceneInfo of the walk-through, from `ready`
  defaults: {}, // the scene's painting settings, engine defaults filled in
  walk: null, // the walk camera (camera.js)
  speed: 1, // scene units per second
  velocity: [0, 0, 0], // forward, right, up: scene units per second
  paint: {}, // the painting settings the user changed (sent as `paint`)
  temporal: true,
  animate: false,
  quality: Number(query.get("quality")) || 80,
  resolution: 1, // painting size as a fraction of the window's
  size: [0, 0], // painting size in pixels: what `hello` and `view` ask for, what Save renders
  time: 0, // scene time of the frame shown (Save paints the same moment)
  cameraId: 0,
  lastCamera: null, // the camera last sent (or the scene's, which the server starts from)
  frame: null, // description of the frame shown
};

const stats = { frames: 0, received: 0, shownAt: [], latencies: [], errors: [], readies: 0 };
const sent = []; // the last 500 messages sent, for the tests
const pendingCameras = new Map(); // camera id -> when it was sent (ms)

// ---- sending ----

function send(msg) {
  if (!connection.send(msg)) return false;
  sent.push(msg);
  if (sent.length > 500) sent.shift();
  return true;
}

function sendCamera() {
  const camera = walkCamera.toCamera(state.walk);
  if (walkCamera.sameCamera(camera, state.lastCamera)) return;
  state.cameraId += 1;
  if (send(MESSAGES.camera(camera, state.cameraId))) {
    pendingCameras.set(state.cameraId, performance.now());
    state.lastCamera = camera;
  }
}

function sendHello() {
  const [width, height] = state.size;
  send(MESSAGES.hello(state.sceneName, width, height, state.quality));
}

// ---- the connection ----

const wsUrl = new URL("ws", location.href);
wsUrl.protocol = wsUrl.protocol === "https:" ? "wss:" : "ws:";

const connection = new Connection(wsUrl.href, {
  onOpen: sendHello,
  onMessage: receive,
  onFrame: frameArrived,
  onState: showConnection,
});

function receive(msg) {
  if (msg.type === "ready") ready(msg);
  else if (msg.type === "error") refused(msg.message);
}

// The server keeps its old settings when it refuses a paint message. Errors do not say which message they
// answer, so one naming a field of the paint message just sent undoes that message in the panel too.
let lastPaint = null; // {changes, before: state.paint as it was, at: ms}

function refused(text) {
  const fields = lastPaint && performance.now() - lastPaint.at < 5000 ? Object.keys(lastPaint.changes) : [];
  if (fields.some((name) => text.includes(name))) {
    for (const name of fields) {
      if (name in lastPaint.before) state.paint[name] = lastPaint.before[name];
      else delete state.paint[name];
    }
    panel.show(state.paint);
    lastPaint = null;
    text = `Refused: ${text}`;
  }
  problem(text);
}

function ready(msg) {
  connection.healthy();
  stats.readies += 1;
  const fresh = state.scene?.name !== msg.scene.name;
  state.scene = msg.scene;
  if (fresh) {
    startScene(msg.scene);
  } else {
    // a reconnection: the server starts afresh, so restore the camera and settings we had
    state.lastCamera = walkCamera.toCamera(walkCamera.fromCamera(msg.scene.camera));
    sendCamera();
    // one field a message: a setting the server refuses does not take the others with it
    for (const [name, value] of Object.entries(state.paint)) send(MESSAGES.paint({ [name]: value }));
  }
  if (msg.temporal !== state.temporal || msg.animate !== state.animate) {
    send(MESSAGES.mode(state.temporal, state.scene.animated && state.animate));
  }
  if (msg.quality !== state.quality) send(MESSAGES.view(undefined, undefined, state.quality));
}

function startScene(scene) {
  state.walk = walkCamera.fromCamera(scene.camera);
  state.lastCamera = walkCamera.toCamera(state.walk); // what the server shows after hello
  state.speed = Math.min(50, Math.max(0.5, state.walk.distance * 0.15));
  state.velocity = [0, 0, 0];
  state.paint = {};
  state.defaults = { ...ENGINE_DEFAULTS, z0: Number(state.walk.distance.toPrecision(3)), ...scene.paint };
  panel.setScene(state.defaults);
  $("scene").value = scene.name;
  $("animate").disabled = !scene.animated;
  $("animate-row").classList.toggle("disabled", !scene.animated);
  $("scene-info").textContent = `${scene.triangles.toLocaleString()} triangles${scene.animated ? " · animated" : ""}`;
  document.title = `${scene.title} · rcp`;
}

function switchScene(name) {
  state.sceneName = name;
  state.scene = null; // the `ready` that follows starts the scene afresh
  const url = new URL(location.href);
  url.searchParams.set("scene", name);
  history.replaceState(null, "", url);
  sendHello();
}

// ---- frames: decode only the newest, draw it scaled to the canvas ----

let newest = null; // the newest frame not yet decoded
let decoding = false;
let shownBitmap = null;

function frameArrived(meta, jpeg) {
  stats.received += 1;
  newest = { meta, jpeg };
  if (!decoding) decodeNewest();
}

async function decodeNewest() {
  decoding = true;
  while (newest) {
    const { meta, jpeg } = newest;
    newest = null; // a frame arriving while this one decodes replaces it
    try {
      const bitmap = await createImageBitmap(new Blob([jpeg], { type: "image/jpeg" }));
      show(meta, bitmap);
    } catch (error) {
      problem(`a frame could not be decoded: ${error.message}`);
    }
  }
  decoding = false;
}

function show(meta, bitmap) {
  shownBitmap?.close();
  shownBitmap = bitmap;
  draw();
  const now = performance.now();
  stats.frames += 1;
  stats.shownAt.push(now);
  while (stats.shownAt[0] < now - 1000) stats.shownAt.shift();
  const sentAt = pendingCameras.get(meta.camera_id);
  if (sentAt !== undefined) {
    stats.latencies.push(now - sentAt);
    if (stats.latencies.length > LATENCY_SAMPLES) stats.latencies.shift();
    for (const id of pendingCameras.keys()) if (id <= meta.camera_id) pendingCameras.delete(id);
  }
  state.frame = meta;
  state.time = meta.time;
  $("hint").classList.toggle("away", stats.frames > 0 && state.moved);
}

function draw() {
  if (!shownBitmap) return;
  context.imageSmoothingEnabled = true;
  context.imageSmoothingQuality = "high";
  context.drawImage(shownBitmap, 0, 0, canvas.width, canvas.height);
}

// ---- the painting's size ----

function wantedSize() {
  const fixed = [Number(query.get("width")), Number(query.get("height"))];
  const base = fixed[0] > 0 && fixed[1] > 0 ? fixed : [innerWidth, innerHeight];
  return base.map((n) => Math.max(16, Math.min(4096, Math.round(n * state.resolution))));
}

function applySize() {
  const size = wantedSize();
  if (size[0] === state.size[0] && size[1] === state.size[1]) return false;
  state.size = size;
  [canvas.width, canvas.height] = size;
  draw();
  return true;
}

let resizeTimer = 0;
addEventListener("resize", () => {
  clearTimeout(resizeTimer);
  resizeTimer = setTimeout(() => {
    if (applySize() && state.scene) send(MESSAGES.view(state.size[0], state.size[1], state.quality));
  }, 250);
});

// ---- walking: keys, mouse, wheel, touch ----

const held = new Set();
/** Keys a focused control needs for itself: typing into boxes, arrows on sliders. Other keys still walk. */
function forControl(event) {
  const target = event.target;
  if (target.matches?.("textarea, select, input[type=number], input[type=text]")) return true;
  return target.matches?.("input[type=range]") && event.code.startsWith("Arrow");
}

addEventListener("keydown", (event) => {
  if (forControl(event) || event.ctrlKey || event.metaKey || event.altKey) return;
  const code = event.code;
  if (code === "KeyR") resetCamera();
  else if (code === "KeyL") lockPointer();
  else if (code === "KeyP") togglePanel();
  else if (!MOVES[code] && !TURNS[code] && !code.startsWith("Shift")) return;
  held.add(code);
  state.moved = true;
  event.preventDefault();
});
addEventListener("keyup", (event) => held.delete(event.code));
addEventListener("blur", () => held.clear());

const MOVES = { KeyW: [1, 0, 0], KeyS: [-1, 0, 0], KeyD: [0, 1, 0], KeyA: [0, -1, 0], KeyE: [0, 0, 1], KeyQ: [0, 0, -1] };
const TURNS = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, 1], ArrowDown: [0, -1] };

function look(dx, dy) {
  const k = LOOK_PER_PIXEL * (state.walk.fov / 60);
  state.walk = walkCamera.turned(state.walk, dx * k, -dy * k);
  state.moved = true;
}

function lockPointer() {
  const request = canvas.requestPointerLock?.();
  request?.catch?.(() => problem("the browser refused to lock the mouse pointer"));
}

const touches = new Map(); // pointer id -> last position, for touch screens
let dragging = false;

canvas.addEventListener("pointerdown", (event) => {
  canvas.focus();
  if (event.pointerType === "touch") touches.set(event.pointerId, [event.clientX, event.clientY]);
  else dragging = true;
  canvas.setPointerCapture(event.pointerId);
});
canvas.addEventListener("pointermove", (event) => {
  if (!state.walk) return;
  if (event.pointerType === "touch") return touchMoved(event);
  if (dragging || document.pointerLockElement === canvas) look(event.movementX, event.movementY);
});
const pointerUp = (event) => {
  touches.delete(event.pointerId);
  if (event.pointerType !== "touch") dragging = false;
};
canvas.addEventListener("pointerup", pointerUp);
canvas.addEventListener("pointercancel", pointerUp);
canvas.addEventListener("dblclick", lockPointer);
canvas.addEventListener("contextmenu", (event) => event.preventDefault());

function touchMoved(event) {
  const last = touches.get(event.pointerId);
  if (!last) return;
  const [dx, dy] = [event.clientX - last[0], event.clientY - last[1]];
  touches.set(event.pointerId, [event.clientX, event.clientY]);
  if (touches.size === 1) look(-dx, -dy); // one finger drags the world: the view turns the other way
  else if (touches.size === 2) {
    // two fingers: each finger's move counts half, so the pair moves the camera by their mean motion
    const step = (state.speed / 150) * 0.5;
    state.walk = walkCamera.moved(state.walk, [-dy * step, -dx * step, 0]);
    state.moved = true;
  }
}

canvas.addEventListener(
  "wheel",
  (event) => {
    if (!state.walk) return;
    event.preventDefault();
    const delta = event.deltaY || event.deltaX; // Shift+wheel scrolls sideways in some browsers
    if (event.shiftKey) {
      state.speed = Math.min(500, Math.max(0.01, state.speed * Math.exp(-delta * 0.002)));
      problem(`walking speed ${state.speed.toPrecision(2)} units/s`, "info");
    } else {
      const [low, high] = walkCamera.FOV_RANGE;
      state.walk = { ...state.walk, fov: Math.min(high, Math.max(low, state.walk.fov * Math.exp(delta * 0.001))) };
    }
    state.moved = true;
  },
  { passive: false },
);

function resetCamera() {
  if (!state.scene) return;
  state.walk = walkCamera.fromCamera(state.scene.camera);
  state.velocity = [0, 0, 0];
}

// ---- the animation loop: move, send at most one camera a frame, refresh the overlay ----

let lastTick = performance.now();
let lastOverlay = 0;

function tick(now) {
  const dt = Math.min(0.1, (now - lastTick) / 1000);
  lastTick = now;
  if (state.walk) {
    walkStep(dt);
    if (state.scene && connection.state === "open") sendCamera();
  }
  flushPaint();
  if (now - lastOverlay > 200) {
    lastOverlay = now;
    updateOverlay(now);
  }
  requestAnimationFrame(tick);
}

function walkStep(dt) {
  const target = [0, 0, 0];
  for (const code of held) MOVES[code]?.forEach((v, k) => (target[k] += v));
  const fast = held.has("ShiftLeft") || held.has("ShiftRight") ? FAST : 1;
  const speed = state.speed * fast;
  const ease = 1 - Math.exp(-EASE * dt);
  state.velocity = state.velocity.map((v, k) => {
    const next = v + (target[k] * speed - v) * ease;
    return target[k] === 0 && Math.abs(next) < 0.02 * state.speed ? 0 : next;
  });
  if (state.velocity.some((v) => v !== 0)) {
    state.walk = walkCamera.moved(state.walk, state.velocity.map((v) => v * dt));
  }
  let [yaw, pitch] = [0, 0];
  for (const code of held) {
    const turn = TURNS[code];
    if (turn) [yaw, pitch] = [yaw + turn[0], pitch + turn[1]];
  }
  if (yaw || pitch) {
    const k = state.walk.fov / 60;
    state.walk = walkCamera.turned(state.walk, yaw * TURN_RATE[0] * k * dt, pitch * TURN_RATE[1] * k * dt);
  }
}

// ---- the panel ----

let paintChanges = {}; // edits of this animation frame, sent together
const panel = paintPanel($("paint"), (name, value) => {
  if (value === null) delete state.paint[name];
  else state.paint[name] = value;
  paintChanges[name] = value;
});

let paintBefore = {}; // state.paint before this frame's edits

function flushPaint() {
  if (!Object.keys(paintChanges).length || !state.scene) {
    paintBefore = { ...state.paint };
    return;
  }
  if (send(MESSAGES.paint(paintChanges))) lastPaint = { changes: paintChanges, before: paintBefore, at: performance.now() };
  paintChanges = {};
  paintBefore = { ...state.paint };
}

function togglePanel() {
  const collapsed = $("panel").classList.toggle("collapsed");
  $("panel-toggle").setAttribute("aria-expanded", String(!collapsed));
}

$("panel-toggle").addEventListener("click", togglePanel);
$("scene").addEventListener("change", (event) => {
  event.target.blur(); // keys walk again
  switchScene(event.target.value);
});
$("reset-camera").addEventListener("click", resetCamera);
$("reset-paint").addEventListener("click", () => {
  for (const name of Object.keys(state.paint)) paintChanges[name] = null; // sent with this frame's edits
  state.paint = {};
  panel.show({});
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
  if (applySize() && state.scene) send(MESSAGES.view(state.size[0], state.size[1], state.quality));
});
$("save").addEventListener("click", save);

// ---- Save: the same view, painted once more at full size with more samples, as a PNG download ----

async function save() {
  if (!state.scene) return;
  const button = $("save");
  const spp = state.paint.spp ?? state.defaults.spp ?? 1;
  const paint = MESSAGES.paint({ ...state.paint, spp: Math.min(64, Math.max(4, 2 * spp)) }); // as refined at rest
  delete paint.type;
  const [width, height] = state.size;
  const body = {
    scene: state.scene.name,
    width,
    height,
    camera: walkCamera.toCamera(state.walk),
    paint,
    time: state.time,
    format: "png",
  };
  button.disabled = true;
  button.textContent = "Painting…";
  try {
    const response = await fetch("api/render", {
      method: "POST",
      headers: { "content-type": "application/json" },
      body: JSON.stringify(body),
    });
    if (!response.ok) {
      const detail = (await response.json().catch(() => ({}))).detail;
      throw new Error(typeof detail === "string" ? detail : detail?.[0]?.msg ?? `HTTP ${response.status}`);
    }
    const link = document.createElement("a");
    link.href = URL.createObjectURL(await response.blob());
    const stamp = new Date().toISOString().slice(0, 19).replace(/[-:]/g, "").replace("T", "-");
    link.download = `rcp-${state.scene.name}-${stamp}.png`;
    link.click();
    setTimeout(() => URL.revokeObjectURL(link.href), 30000);
  } catch (error) {
    problem(`Save failed: ${error.message}`);
  } finally {
    button.disabled = false;
    button.textContent = "Save PNG";
  }
}

// ---- the overlay and messages to the user ----

function showConnection(connectionState, detail) {
  const words = {
    connecting: "connecting…",
    open: "connected",
    waiting: `${detail.why} · retry in ${detail.seconds?.toFixed(1)} s`,
    stopped: "stopped",
  };
  $("o-connection").textContent = words[connectionState] ?? connectionState;
  $("overlay").dataset.connection = connectionState;
}

function median(values) {
  if (!values.length) return null;
  const sorted = [...values].sort((a, b) => a - b);
  const mid = sorted.length >> 1;
  return sorted.length % 2 ? sorted[mid] : (sorted[mid - 1] + sorted[mid]) / 2;
}

function updateOverlay(now) {
  while (stats.shownAt.length && stats.shownAt[0] < now - 1000) stats.shownAt.shift();
  const f = state.frame;
  const latency = median(stats.latencies);
  $("o-fps").textContent = stats.shownAt.length;
  $("o-latency").textContent = latency === null ? "–" : `${Math.round(latency)} ms`;
  $("o-frames").textContent = stats.frames;
  if (!f) return;
  $("o-size").textContent = `${f.width}×${f.height}`;
  $("o-scale").textContent = f.scale === 1 ? "full" : `×${f.scale.toFixed(2)}`;
  $("o-render").textContent = `${Math.round(f.render_ms)} ms`;
  $("o-phase").textContent = f.phase === "refine" ? (f.final ? "refined" : "refining") : "walk";
  $("o-phase").dataset.phase = f.final ? "final" : f.phase;
  $("o-iteration").textContent = `${f.iteration}${f.temporal ? " (temporal)" : ""}`;
  $("o-spp").textContent = f.spp;
  $("o-dropped").textContent = f.dropped;
}

let toastTimer = 0;
function problem(text, kind = "error") {
  if (kind === "error") {
    stats.errors.push(text);
    if (stats.errors.length > 50) stats.errors.shift();
  }
  const toast = $("toast");
  toast.textContent = text;
  toast.dataset.kind = kind;
  toast.classList.add("shown");
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => toast.classList.remove("shown"), kind === "error" ? 7000 : 1500);
}

// ---- start: the scene list, then the walk-through ----

async function loadScenes() {
  for (let wait = 500; ; wait = Math.min(wait * 2, 8000)) {
    try {
      const response = await fetch("api/scenes");
      if (response.ok) return await response.json();
    } catch {
      // the server is not up yet: try again
    }
    $("o-connection").textContent = "waiting for the server…";
    await new Promise((resolve) => setTimeout(resolve, wait));
  }
}

async function start() {
  if (matchMedia("(max-width: 700px)").matches) togglePanel();
  if (matchMedia("(pointer: coarse)").matches) $("hint").textContent = "One finger looks · two fingers move";
  $("quality").value = state.quality;
  $("quality-value").textContent = state.quality;
  applySize();
  state.scenes = await loadScenes();
  const names = state.scenes.map((s) => s.name);
  const select = $("scene");
  for (const scene of state.scenes) select.append(new Option(`${scene.title} (${scene.name})`, scene.name));
  if (!names.includes(state.sceneName)) {
    if (state.sceneName) problem(`no scene '${state.sceneName}' here; showing another`);
    state.sceneName = names.includes("default") ? "default" : names[0];
  }
  if (!state.sceneName) return problem("the server has no scenes");
  connection.start();
  requestAnimationFrame(tick);
}

window.rcp = { state, stats, sent, connection, MESSAGES, PROTOCOL, ENGINE_DEFAULTS, panel, canvas };
start();
