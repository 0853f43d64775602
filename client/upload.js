// @ts-check
// Your own scenes: drop a model on the page (or pick one), watch it upload, then walk through it.
//
// POST api/scenes with the file (XMLHttpRequest, for its upload progress); the answer describes the new
// scene, whose name only this browser knows: it is kept in localStorage and listed under "Your scenes" in
// the scene list, until the server has forgotten it (uploaded scenes are removed after some idle time).

const KINDS = [".glb", ".gltf", ".obj", ".ply", ".stl", ".zip"];
const STORE = "rcp-uploads"; // [{name, title}] of this browser's uploads

export class Uploader {
  /**
   * @param {HTMLSelectElement} select  the scene list: uploaded scenes go in its "Your scenes" group
   * @param {object} authorization      headers that carry the token, if any
   * @param {object} handlers           chosen(name): walk through it; notice(text, kind)
   */
  constructor(select, authorization, handlers) {
    this.select = select;
    this.authorization = authorization;
    this.handlers = handlers;
    this.group = document.createElement("optgroup");
    this.group.label = "Your scenes";
    this.input = /** @type {HTMLInputElement} */ (document.getElementById("upload-file"));
    this.progress = /** @type {HTMLProgressElement} */ (document.getElementById("upload-progress"));
    this.status = document.getElementById("upload-status");
    this.busy = false;
    this.uploads = 0; // finished uploads (the tests watch it)
    this.input.addEventListener("change", () => {
      if (this.input.files.length) this.upload(this.input.files[0]);
      this.input.value = "";
    });
    this.dropZone(document.getElementById("drop"));
  }

  /** The uploads this browser remembers that the server still has, listed; returns their names. */
  async restore() {
    const kept = [];
    for (const { name } of remembered()) {
      const response = await fetch(`api/scenes/${encodeURIComponent(name)}`, { headers: this.authorization }).catch(
        () => null,
      );
      if (response?.ok) kept.push(await response.json());
    }
    localStorage.setItem(STORE, JSON.stringify(kept.map(({ name, title }) => ({ name, title }))));
    for (const scene of kept) this.list(scene);
    return kept.map((scene) => scene.name);
  }

  list(scene) {
    if (!this.group.parentNode) this.select.append(this.group);
    if (![...this.group.querySelectorAll("option")].some((option) => option.value === scene.name)) {
      this.group.append(new Option(`${scene.title} (yours)`, scene.name));
    }
  }

  dropZone(zone) {
    let depth = 0; // dragenter and dragleave come for every child element crossed
    const carriesFiles = (event) => [...(event.dataTransfer?.types ?? [])].includes("Files");
    addEventListener("dragenter", (event) => {
      if (!carriesFiles(event)) return;
      depth += 1;
      zone.classList.add("shown");
    });
    addEventListener("dragleave", () => {
      depth = Math.max(0, depth - 1);
      if (!depth) zone.classList.remove("shown");
    });
    addEventListener("dragover", (event) => {
      if (carriesFiles(event)) event.preventDefault(); // or the browser opens the file itself
    });
    addEventListener("drop", (event) => {
      depth = 0;
      zone.classList.remove("shown");
      if (!carriesFiles(event)) return;
      event.preventDefault();
      const file = event.dataTransfer.files[0];
      if (file) this.upload(file);
    });
  }

  /** Send one model; on success walk through it. Resolves to the scene's description, or null. */
  upload(file) {
    const kind = file.name.slice(file.name.lastIndexOf(".")).toLowerCase();
    if (!KINDS.includes(kind)) {
      this.handlers.notice(`${file.name}: not a model this server reads (${KINDS.join(", ")})`);
      return Promise.resolve(null);
    }
    if (this.busy) {
      this.handlers.notice("one upload at a time: wait for the one under way");
      return Promise.resolve(null);
    }
    this.busy = true;
    this.show(0, `uploading ${file.name}…`);
    const form = new FormData();
    form.append("file", file, file.name);
    const request = new XMLHttpRequest();
    request.open("POST", "api/scenes");
    for (const [header, value] of Object.entries(this.authorization)) request.setRequestHeader(header, value);
    request.responseType = "json";
    request.upload.addEventListener("progress", (event) => {
      if (event.lengthComputable) this.show(event.loaded / event.total, `uploading ${file.name}…`);
    });
    // sent: the server reads the model in its sandbox, which can take a few seconds
    request.upload.addEventListener("load", () => this.show(null, `reading ${file.name}…`));
    return new Promise((resolve) => {
      const finish = (scene, problem) => {
        this.busy = false;
        this.uploads += 1;
        this.show(undefined, scene ? `${scene.title}: ${scene.triangles.toLocaleString()} triangles` : "");
        if (problem) this.handlers.notice(`Upload refused: ${problem}`);
        if (scene) {
          this.list(scene);
          localStorage.setItem(STORE, JSON.stringify([...remembered(), { name: scene.name, title: scene.title }]));
          this.handlers.chosen(scene.name);
        }
        resolve(scene);
      };
      request.addEventListener("load", () => {
        const detail = request.response?.detail;
        if (request.status === 201) finish(request.response, null);
        else finish(null, typeof detail === "string" ? detail : `HTTP ${request.status}`);
      });
      request.addEventListener("error", () => finish(null, "the connection failed"));
      request.send(form);
    });
  }

  /** The progress bar: a fraction, null for "busy, no figure", undefined to hide it. */
  show(fraction, text) {
    this.progress.hidden = fraction === undefined;
    if (fraction === null) this.progress.removeAttribute("value");
    else if (fraction !== undefined) this.progress.value = fraction;
    this.status.textContent = text;
  }
}

function remembered() {
  try {
    const kept = JSON.parse(localStorage.getItem(STORE) ?? "[]");
    return Array.isArray(kept) ? kept.filter((s) => typeof s?.name === "string") : [];
  } catch {
    return [];
  }
}
