// @ts-check
// The page's state: what the walk-through shows and what the user chose, in one object the other modules
// read and write (and the tests read as `rcp.state`), and the one way the page tells the user something.

/**
 * The state at start, from the page's address as link.js read it.
 * @param {{scene: string | null, switches: Object<string, boolean>, page: {quality?: number, resolution?: number}}} link
 */
export function initialState(link) {
  return {
    /** @type {import("./protocol.js").SceneInfo[]} every scene (GET /api/scenes) */
    scenes: [],
    sceneName: link.scene,
    /** @type {import("./protocol.js").SceneInfo | null} the walk-through's, from `ready` */
    scene: null,
    /** @type {import("./protocol.js").RefineRule | null} how the server refines a view at rest, from `ready` */
    refine: null,
    /** @type {Object<string, any>} the scene's painting settings, engine defaults filled in */
    defaults: {},
    /** @type {Object<string, any>} the painting settings the user changed (sent as `paint`), a style among them */
    paint: {},
    /** @type {{changes: Object<string, any>, before: Object<string, any>} | null} the last paint message sent */
    lastPaint: null,
    /** @type {{paint: Object<string, any>, camera: any} | null} the camera path's painting the walk shows in place
     * of the page's own settings of those names, at the view scrubbed to (path/scrub.js), until it moves on */
    keyed: null,
    /** @type {Object<string, any>} name -> StyleInfo (GET /api/styles) */
    styles: {},
    temporal: false, // per-frame: every frame is the painting of its camera
    animate: false,
    quality: link.page.quality ?? 80,
    resolution: link.page.resolution ?? 1, // painting size as a fraction of the window's (or of ?width, ?height)
    collide: link.switches.collide ?? true, // walking, not flying (collide.js)
    gravity: link.switches.gravity ?? false,
    size: [0, 0], // painting size in pixels: what `hello` and `view` ask for, what Save renders
    cameraId: 0,
    /** @type {any} the camera last sent (or the scene's, which the server starts from) */
    lastCamera: null,
    atBound: false, // the walk stands at the edge of the space the server paints (said once)
    readies: 0, // `ready` messages received
    messages: 0, // messages sent since the page opened (`sent` keeps only the last 500)
    /** @type {string[]} the last 50 problems shown to the user */
    errors: [],
  };
}

/** @typedef {ReturnType<typeof initialState>} State */

const ERRORS_KEPT = 50;

/**
 * The one line the page shows the user (the toast); errors are kept in `state.errors` too.
 * @param {State} state
 * @param {HTMLElement} toast
 */
export function notifier(state, toast) {
  let timer = 0;
  /** @param {string} text @param {"error" | "info"} [kind] */
  return function notice(text, kind = "error") {
    if (kind === "error") {
      state.errors.push(text);
      if (state.errors.length > ERRORS_KEPT) state.errors.shift();
    }
    toast.textContent = text;
    toast.dataset.kind = kind;
    toast.classList.add("shown");
    clearTimeout(timer);
    timer = window.setTimeout(() => toast.classList.remove("shown"), kind === "error" ? 7000 : 1500);
  };
}
