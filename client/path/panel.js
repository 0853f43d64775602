// @ts-check
// The camera path panel: keyframes taken from the walk (one at a time, or recorded while walking: recorder.js),
// moved to the current view or deleted (list.js), played back as the video will show them (player.js), saved
// and loaded as the JSON that `rcp render --path` and POST /api/videos read (files.js), and rendered to an MP4
// by the server with a progress bar (film.js), flat or 360° at a chosen size (sizes.js).
//
// The keys also show on a timeline (timeline.js: drag to retime, click to select, scrub to see the path at a
// time, scrub.js), the selected one's values are typed in (editor.js: camera, ease, painting), a model's
// animated camera may become the path (motions.js), and every change can be undone and redone (keys.js,
// history.js). This module only puts the parts together.

import { button, caller } from "./api.js";
import { keyEditor } from "./editor.js";
import { Film } from "./film.js";
import { readPath, savePath } from "./files.js";
import { PathKeys, keyOf } from "./keys.js";
import { keyList } from "./list.js";
import { motionChooser } from "./motions.js";
import { Player } from "./player.js";
import { Recorder } from "./recorder.js";
import { Scrubber } from "./scrub.js";
import { FilmSize } from "./sizes.js";
import { timeline } from "./timeline.js";

/**
 * The path panel in `root`. `hooks`: camera() -> the current view ({eye, look_at, up, fov}); place(camera)
 * moves the walk there; keyed(table) has the walk paint the path's painting there (a paint table; null: the
 * page's own); scene() -> the SceneInfo shown (or null); request() -> {paint, width, height} of a
 * render; viewSize(film) -> the view's painting size as that film takes it; authorization (headers);
 * notice(text, kind).
 * @param {HTMLElement} root @param {any} hooks
 */
export function pathPanel(root, hooks) {
  return new PathPanel(root, hooks);
}

class PathPanel {
  /** @param {HTMLElement} root @param {any} hooks */
  constructor(root, hooks) {
    this.hooks = hooks;
    /** @type {(name: string) => any} */
    this.$ = (name) => root.querySelector(`[data-path="${name}"]`);
    const $ = this.$;
    this.call = caller(hooks.authorization);
    this.keys = new PathKeys(() => this.show());
    this.sizes = new FilmSize($("film"), $("size"), hooks.viewSize);
    this.recorder = new Recorder($("record"), {
      begin: () => {
        this.player.stop();
        this.keys.replace([]);
      },
      take: (t) => this.add(t),
    });
    this.player = new Player($("play"), {
      cameras: () => this.cameras(),
      place: hooks.place,
      keyed: hooks.keyed,
      loop: () => $("loop").checked,
      notice: hooks.notice,
    });
    this.film = new Film($, {
      call: this.call,
      download: (url) => fetch(url, { headers: hooks.authorization }).then((response) => response.blob()),
      name: () => `rcp-${hooks.scene()?.name ?? "path"}.mp4`,
      changed: () => this.show(),
      notice: hooks.notice,
    });
    this.scrubber = new Scrubber({
      spec: () => this.spec(),
      paint: () => hooks.request().paint,
      scene: hooks.scene,
      call: this.call,
      stop: () => this.player.stop(),
      place: hooks.place,
      keyed: hooks.keyed,
      notice: hooks.notice,
    });
    this.list = keyList($("list"), {
      keys: () => this.keys.keyframes,
      change: (index, fields) => this.keys.change(index, fields),
      remove: (index) => this.keys.remove(index),
      select: (index) => this.keys.select(index),
      look: hooks.place,
      here: () => this.snapshot(),
    });
    this.tools($("list"));
    this.wire();
    this.show();
    this.sizes.show();
  }

  /** The timeline, the undo buttons, the selected key's values and the animated cameras, under the list. */
  tools(list) {
    const tools = document.createElement("div");
    tools.className = "path-tools";
    list.after(tools);
    const keys = this.keys;
    this.line = timeline(tools, {
      keys: () => keys.keyframes,
      selected: () => keys.selected,
      select: (index) => keys.select(index),
      retime: (index, t) => keys.change(index, { t }),
      scrub: (t) => this.scrubber.scrub(t),
    });
    this.editor = keyEditor(tools, {
      key: () => keys.keyframes[keys.selected] ?? null,
      change: (fields) => keys.change(keys.selected, fields),
      notice: this.hooks.notice,
    });
    const undoing = document.createElement("div");
    undoing.className = "buttons";
    for (const [name, text, act] of /** @type {Array<[string, string, () => void]>} */ ([
      ["undo", "Undo", () => keys.history.undo()],
      ["redo", "Redo", () => keys.history.redo()],
    ])) {
      const b = button(text, `${text} the last change of the path`, act);
      b.dataset.path = name;
      undoing.append(b);
    }
    this.line.scrub.after(undoing);
    this.motions = motionChooser(tools, {
      scene: this.hooks.scene,
      fps: () => Number(this.$("fps").value) || 24,
      call: this.call,
      take: (keys) => this.keys.replace(keys),
      notice: this.hooks.notice,
    });
  }

  /** The buttons and fields of the panel's own markup (index.html). */
  wire() {
    const $ = this.$;
    const on = (name, action) =>
      $(name).addEventListener("click", (event) => {
        event.target.blur();
        action();
      });
    on("add", () => this.add());
    on("record", () => this.recorder.record());
    on("play", () => this.play());
    on("clear", () => {
      this.player.stop();
      this.keys.replace([]);
    });
    on("save", () => savePath(this.spec(), `rcp-path-${this.hooks.scene()?.name ?? "scene"}.json`));
    on("open", () => $("file").click());
    on("render", () => this.render());
    on("cancel", () => this.film.cancel());
    $("film").addEventListener("change", (event) => {
      event.target.blur();
      this.sizes.show();
    });
    $("size").addEventListener("focus", () => this.sizes.show()); // the view's size may have changed since
    $("file").addEventListener("change", (event) => {
      if (event.target.files[0]) this.load(event.target.files[0]);
      event.target.value = "";
    });
  }

  show() {
    const $ = this.$;
    this.list.draw();
    const count = this.keys.keyframes.length;
    const end = count ? this.keys.keyframes.at(-1).t : 0;
    $("summary").textContent = count ? `${count} keyframes · ${end.toFixed(1)} s` : "no keyframes yet";
    for (const name of ["play", "save", "render"]) $(name).disabled = count < 2 || Boolean(this.film.job && name === "render");
    $("clear").disabled = count === 0;
    this.line.draw();
    this.editor.draw();
    this.motions.draw();
  }

  /** A keyframe's fields at the current view. */
  snapshot() {
    const { t, ...fields } = keyOf(this.hooks.camera(), 0);
    return fields;
  }

  /** A keyframe of the current view at `t` seconds (default: a second after the last). @param {number} [t] */
  add(t) {
    const key = keyOf(this.hooks.camera(), t ?? this.keys.next());
    if (key.projection === "equirect" && this.$("film").value !== "equirect") this.sizes.set("equirect"); // a 360° film
    this.keys.push(key, !this.recorder.active); // a recording is one step to undo, taken as it starts
  }

  /** The path as the CLI and REST take it: a 360° film's keyframes are panoramas, a flat one's are not. */
  spec() {
    const film = this.$("film").value;
    const keyframes = this.keys.keyframes.map(({ projection, stereo, ...key }) =>
      film === "equirect" ? { ...key, projection: "equirect", stereo: "mono" } : key,
    );
    return { fps: Number(this.$("fps").value) || 24, loop: this.$("loop").checked, keyframes };
  }

  /** The server's cameras of the path's frames, and the painting it keys for each over the film's. */
  async cameras() {
    const scene = this.hooks.scene();
    if (!scene) throw new Error("no scene yet");
    return this.call("api/paths", "POST", { scene: scene.name, path: this.spec(), paint: this.hooks.request().paint });
  }

  play() {
    this.recorder.stop();
    if (!this.hooks.scene() && !this.player.playing) return;
    this.player.play();
  }

  async load(file) {
    try {
      const loaded = await readPath(file);
      this.keys.replace(loaded.keyframes);
      this.sizes.set(loaded.film);
      this.$("fps").value = loaded.fps;
      this.$("loop").checked = loaded.loop;
      this.show();
      this.hooks.notice(`Loaded ${loaded.keyframes.length} keyframes`, "info");
    } catch (error) {
      this.hooks.notice(`Cannot load ${file.name}: ${error.message}`);
    }
  }

  render() {
    const scene = this.hooks.scene();
    if (!scene || this.film.job) return;
    this.recorder.stop();
    const { paint } = this.hooks.request();
    const [width, height] = this.sizes.chosen();
    const body = { scene: scene.name, path: this.spec(), width, height, paint, format: "mp4" };
    if (this.$("temporal").checked) body.temporal = 1;
    this.film.submit(body);
  }

  // ---- what the page and its tests read ----

  get path() {
    return this.keys.path;
  }
  get history() {
    return this.keys.history;
  }
  get progress() {
    return this.film.progress;
  }
  get playing() {
    return this.player.playing;
  }
  get selected() {
    return this.keys.selected;
  }
  get scrubbed() {
    return this.scrubber.scrubbed;
  }
  get job() {
    return this.film.job;
  }
  select(index) {
    this.keys.select(index);
  }
  showSizes() {
    this.sizes.show();
  }
}
