// The camera path: keyframes taken from the walk (one at a time, or recorded while walking), moved to the
// current view or deleted, played back as the video will show them, saved and loaded as the JSON that
// `rcp render --path` and POST /api/videos read, and rendered to an MP4 by the server with a progress bar.
//
// Playback asks the server for the cameras of every frame (POST /api/paths): the spline is declared once,
// in rcp_server/media/camerapath.py, so what plays here is what the video paints.
//
// A film is flat or 360° (equirect: every keyframe's camera becomes a panorama at its eye, as the 360° view
// shows), at a size chosen from a list (the view's own first); the render's progress bar follows the job's
// `done_frames`, each value seen kept in `progress` for the tests.
//
// The keys also show on a timeline (path/timeline.js: drag to retime, click to select, scrub to see the path
// at a time), the selected one's values are typed in (path/editor.js: camera, ease, painting), and every
// change can be undone and redone (path/history.js).

import { keyEditor } from "./path/editor.js";
import { motionChooser } from "./path/motions.js";
import { History } from "./path/history.js";
import { timeline } from "./path/timeline.js";

const RECORD_EVERY_S = 0.5; // a keyframe this often while recording: the spline smooths between them
const POLL_MS = 500;

const round = (x) => Math.round(x * 1e4) / 1e4;
const SIZES = {
  perspective: [[640, 360], [1280, 720], [1920, 1080]],
  equirect: [[1024, 512], [2048, 1024], [3840, 1920]],
};
const even = (n) => n - (n % 2); // H.264 in yuv420p takes even sizes

/**
 * The path panel in `root`. `hooks`: camera() -> the current view ({eye, look_at, up, fov}); place(camera)
 * moves the walk there; scene() -> the SceneInfo shown (or null); request() -> {paint, width, height} of a
 * render; authorization (headers); notice(text, kind).
 */
export function pathPanel(root, hooks) {
  const path = { fps: 24, loop: false, keyframes: [] };
  const $ = (name) => root.querySelector(`[data-path="${name}"]`);
  let recording = null; // {start: ms, timer}
  let playing = null; // {cameras, fps, start, frame}
  let job = null; // {id, frames, timer}
  const progress = []; // the progress bar's values during the last render
  let selected = -1; // the keyframe shown in the editor
  let scrubbed = null; // {t, frame}: the last time scrubbed to, and the frame shown
  let preview = null; // {spec, answer}: the server's cameras of the path as it was last scrubbed
  const history = new History(
    () => path.keyframes,
    (keys) => {
      path.keyframes = keys;
      selected = Math.min(selected, keys.length - 1);
      show();
    },
  );

  // ---- keyframes ----

  function snapshot() {
    const { eye, look_at, up, fov, projection, stereo } = hooks.camera();
    const kind = projection ? { projection, stereo } : {}; // a panorama's, in the 360° view: a 360° video
    return { eye: eye.map(round), look_at: look_at.map(round), up: [...up], fov: round(fov), ...kind };
  }

  function add(t) {
    if (!recording) history.record(); // a recording is one step to undo, taken as it starts
    const last = path.keyframes.at(-1);
    const when = t ?? (last ? round(last.t + 1) : 0);
    const key = { t: when, ...snapshot() };
    path.keyframes.push(key);
    if (key.projection === "equirect" && $("film").value !== "equirect") {
      $("film").value = "equirect"; // taken in the 360° view: a 360° film
      showSizes();
    }
    show();
  }

  function show() {
    const list = $("list");
    list.replaceChildren();
    path.keyframes.forEach((key, index) => {
      const row = document.createElement("li");
      row.dataset.index = index;
      const time = document.createElement("input");
      Object.assign(time, { type: "number", min: 0, step: 0.1, value: key.t, title: "seconds along the path" });
      time.addEventListener("change", () => change(index, { t: Math.max(0, Number(time.value) || 0) }));
      row.append(time, button("view", "Look from this keyframe", () => hooks.place(key)));
      row.append(button("set", "Move this keyframe to the current view", () => change(index, snapshot())));
      row.append(button("×", "Delete this keyframe", () => {
        history.record();
        path.keyframes.splice(index, 1);
        selected = -1;
        show();
      }));
      row.addEventListener("click", (event) => {
        if (event.target === row) select(index);
      });
      list.append(row);
    });
    const count = path.keyframes.length;
    const end = count ? path.keyframes.at(-1).t : 0;
    $("summary").textContent = count ? `${count} keyframes · ${end.toFixed(1)} s` : "no keyframes yet";
    for (const name of ["play", "save", "render"]) $(name).disabled = count < 2 || Boolean(job && name === "render");
    $("clear").disabled = count === 0;
    line.draw();
    editor.draw();
    motions.draw();
  }

  // ---- the timeline, the selected keyframe, undo ----

  function select(index) {
    selected = index;
    show();
  }

  /** Typed or dragged values of keyframe `index`, one step to undo; the keys stay in time order. */
  function change(index, fields) {
    const key = path.keyframes[index];
    if (!key) return;
    const before = JSON.stringify(path.keyframes);
    Object.assign(key, fields);
    if (fields.paint === null) delete key.paint;
    if (key.fade === 0) delete key.fade;
    if (key.ease && key.ease.every((e) => e === 0)) delete key.ease;
    path.keyframes.sort((a, b) => a.t - b.t);
    if (selected >= 0) selected = path.keyframes.indexOf(key);
    if (JSON.stringify(path.keyframes) !== before) history.push(before); // the same values again: no step
    show();
  }

  /** The walk shows the path at `t` seconds: the server's camera of the frame there. */
  async function scrub(t) {
    const scene = hooks.scene();
    if (!scene || path.keyframes.length < 2) return;
    stopPlaying();
    const asked = JSON.stringify(spec());
    try {
      if (preview?.spec !== asked) {
        preview = { spec: asked, answer: await call("api/paths", "POST", { scene: scene.name, path: JSON.parse(asked) }) };
      }
      const { cameras, fps } = preview.answer;
      const frame = Math.min(cameras.length - 1, Math.round(t * fps));
      scrubbed = { t, frame };
      hooks.place(cameras[frame]);
    } catch (error) {
      hooks.notice(`Cannot show the path at ${t} s: ${error.message}`);
    }
  }

  const tools = document.createElement("div"); // the timeline, the undo buttons, the selected key's values
  tools.className = "path-tools";
  const undoing = document.createElement("div");
  undoing.className = "buttons";
  $("list").after(tools);
  const line = timeline(tools, {
    keys: () => path.keyframes,
    selected: () => selected,
    select,
    retime: (index, t) => change(index, { t }),
    scrub,
  });
  const editor = keyEditor(tools, {
    key: () => path.keyframes[selected] ?? null,
    change: (fields) => change(selected, fields),
    notice: hooks.notice,
  });
  for (const [name, text, act] of [
    ["undo", "Undo", () => history.undo()],
    ["redo", "Redo", () => history.redo()],
  ]) {
    const b = button(text, `${text} the last change of the path`, act);
    b.dataset.path = name;
    undoing.append(b);
  }
  line.scrub.after(undoing);
  const motions = motionChooser(tools, {
    scene: hooks.scene,
    fps: () => Number($("fps").value) || 24,
    call,
    take: (keys) => {
      history.record();
      path.keyframes = keys;
      selected = -1;
      show();
    },
    notice: hooks.notice,
  });

  function button(text, title, action) {
    const b = document.createElement("button");
    Object.assign(b, { type: "button", textContent: text, title });
    b.addEventListener("click", (event) => {
      event.target.blur(); // keys walk again
      action();
    });
    return b;
  }

  // ---- recording ----

  function record() {
    if (recording) return stopRecording();
    stopPlaying();
    history.record();
    path.keyframes = [];
    recording = { start: performance.now() };
    add(0);
    recording.timer = setInterval(() => add(round((performance.now() - recording.start) / 1000)), RECORD_EVERY_S * 1000);
    $("record").textContent = "Stop recording";
    $("record").setAttribute("aria-pressed", "true");
  }

  function stopRecording() {
    if (!recording) return;
    clearInterval(recording.timer);
    add(round((performance.now() - recording.start) / 1000));
    recording = null;
    $("record").textContent = "Record";
    $("record").setAttribute("aria-pressed", "false");
  }

  // ---- playback ----

  /** The path as the CLI and REST take it: a 360° film's keyframes are panoramas, a flat one's are not. */
  function spec() {
    const film = $("film").value;
    const keyframes = path.keyframes.map(({ projection, stereo, ...key }) =>
      film === "equirect" ? { ...key, projection: "equirect", stereo: "mono" } : key,
    );
    return { fps: Number($("fps").value) || 24, loop: $("loop").checked, keyframes };
  }

  // ---- the film's size ----

  function showSizes() {
    const select = $("size");
    const chosen = select.value;
    const film = $("film").value;
    const [width, height] = hooks.viewSize(film);
    select.replaceChildren(new Option(`the view's (${even(width)}×${even(height)})`, "view"));
    for (const [w, h] of SIZES[film]) select.append(new Option(`${w}×${h}`, `${w}x${h}`));
    select.value = [...select.options].some((o) => o.value === chosen) ? chosen : "view";
  }

  function size() {
    const chosen = $("size").value;
    const [width, height] = chosen === "view" || !chosen ? hooks.viewSize($("film").value) : chosen.split("x").map(Number);
    return [even(width), even(height)];
  }

  async function play() {
    if (playing) return stopPlaying();
    stopRecording();
    const scene = hooks.scene();
    if (!scene) return;
    try {
      const answer = await call("api/paths", "POST", { scene: scene.name, path: spec() });
      playing = { cameras: answer.cameras, fps: answer.fps, start: performance.now(), frame: -1 };
      $("play").textContent = "Stop";
      requestAnimationFrame(step);
    } catch (error) {
      hooks.notice(`Cannot play the path: ${error.message}`);
    }
  }

  function step(now) {
    if (!playing) return;
    let frame = Math.floor(((now - playing.start) / 1000) * playing.fps);
    if (frame >= playing.cameras.length) {
      if (!$("loop").checked) return stopPlaying();
      frame %= playing.cameras.length;
    }
    if (frame !== playing.frame) {
      playing.frame = frame;
      hooks.place(playing.cameras[frame]);
    }
    requestAnimationFrame(step);
  }

  function stopPlaying() {
    playing = null;
    $("play").textContent = "Play";
  }

  // ---- save and load ----

  function save() {
    const link = document.createElement("a");
    link.href = URL.createObjectURL(new Blob([JSON.stringify(spec(), null, 1)], { type: "application/json" }));
    link.download = `rcp-path-${hooks.scene()?.name ?? "scene"}.json`;
    link.click();
    setTimeout(() => URL.revokeObjectURL(link.href), 30000);
  }

  async function load(file) {
    try {
      const loaded = JSON.parse(await file.text());
      if (!Array.isArray(loaded?.keyframes)) throw new Error("no keyframes in it");
      history.record();
      path.keyframes = loaded.keyframes.map((k) => ({ ...k }));
      $("film").value = loaded.keyframes.some((k) => k.projection === "equirect") ? "equirect" : "perspective";
      showSizes();
      $("fps").value = loaded.fps ?? 24;
      $("loop").checked = Boolean(loaded.loop);
      show();
      hooks.notice(`Loaded ${path.keyframes.length} keyframes`, "info");
    } catch (error) {
      hooks.notice(`Cannot load ${file.name}: ${error.message}`);
    }
  }

  // ---- rendering ----

  async function render() {
    const scene = hooks.scene();
    if (!scene || job) return;
    stopRecording();
    const { paint } = hooks.request();
    const [width, height] = size();
    const body = { scene: scene.name, path: spec(), width, height, paint, format: "mp4" };
    if ($("temporal").checked) body.temporal = 1;
    try {
      const created = await call("api/videos", "POST", body);
      job = { id: created.id, frames: created.frames };
      $("progress").max = created.frames;
      $("progress").value = 0;
      progress.splice(0, progress.length, 0);
      $("job").hidden = false;
      $("download").hidden = true;
      $("cancel").hidden = false;
      $("status").textContent = `queued · ${created.frames} frames`;
      show();
      job.timer = setInterval(poll, POLL_MS);
    } catch (error) {
      hooks.notice(`Cannot render the path: ${error.message}`);
    }
  }

  async function poll() {
    if (!job) return;
    let status;
    try {
      status = await call(`api/videos/${job.id}`, "GET");
    } catch (error) {
      return finish(`failed: ${error.message}`);
    }
    if (!job) return; // ended meanwhile (a cancel's poll)
    $("progress").value = status.done_frames;
    if (progress.at(-1) !== status.done_frames) progress.push(status.done_frames);
    $("status").textContent = `${status.state} · ${status.done_frames} / ${status.frames} frames`;
    if (status.state === "done") {
      const response = await fetch(`api/videos/${job.id}/file`, { headers: hooks.authorization });
      const link = $("download");
      link.href = URL.createObjectURL(await response.blob());
      link.download = `rcp-${hooks.scene()?.name ?? "path"}.mp4`;
      link.hidden = false;
      finish("done");
    } else if (status.state === "failed" || status.state === "cancelled") {
      finish(`${status.state}${status.message ? `: ${status.message}` : ""}`);
    }
  }

  function finish(text) {
    if (!job) return; // a cancel's poll and the timer's can both end a job: the first ends it
    clearInterval(job.timer);
    $("cancel").hidden = true;
    $("status").textContent = text;
    job = null;
    show();
  }

  async function cancel() {
    if (!job) return;
    try {
      await call(`api/videos/${job.id}`, "DELETE");
    } catch (error) {
      hooks.notice(`Cannot cancel: ${error.message}`);
    }
    poll();
  }

  async function call(url, method, body) {
    const response = await fetch(url, {
      method,
      headers: { "content-type": "application/json", ...hooks.authorization },
      body: body === undefined ? undefined : JSON.stringify(body),
    });
    const answer = await response.json().catch(() => ({}));
    if (!response.ok) {
      const detail = answer.detail;
      const where = Array.isArray(detail) ? `${detail[0]?.loc?.slice(1).join(".")}: ${detail[0]?.msg}` : detail;
      throw new Error(where ?? `HTTP ${response.status}`);
    }
    return answer;
  }

  // ---- wiring ----

  const on = (name, action) =>
    $(name).addEventListener("click", (event) => {
      event.target.blur();
      action();
    });
  on("add", () => add());
  on("record", record);
  on("play", play);
  on("clear", () => {
    stopPlaying();
    history.record();
    path.keyframes = [];
    selected = -1;
    show();
  });
  on("save", save);
  on("open", () => $("file").click());
  on("render", render);
  on("cancel", cancel);
  $("film").addEventListener("change", (event) => {
    event.target.blur();
    showSizes();
  });
  $("size").addEventListener("focus", showSizes); // the view's size may have changed since
  $("file").addEventListener("change", (event) => {
    if (event.target.files[0]) load(event.target.files[0]);
    event.target.value = "";
  });
  show();
  showSizes();
  return {
    path,
    spec,
    add,
    progress,
    showSizes,
    history,
    select,
    get playing() {
      return playing;
    },
    get selected() {
      return selected;
    },
    get scrubbed() {
      return scrubbed;
    },
    get job() {
      return job;
    },
  };
}
