// @ts-check
// Share links: the page's address carries the view, so that opening it elsewhere shows the same scene, camera
// and painting. main.js writes it as the user walks (history.replaceState, a few times a second at most) and
// reads it once at start.
//
//   ?scene=default&eye=0.8,1.7,38&look_at=0,3,0&fov=60        the scene and the walk's camera
//   &projection=equirect&heading=0.12                          the 360° view, and the heading of its panorama
//   &temporal=1&animate=1&collide=0&gravity=1                  the stream's and the walk's switches
//   &style=ink&lambda_p=20&objects={"walls":{"lambda_p":0}}    every painting setting changed (paint schema)
//   &width=480&height=270&quality=80&resolution=0.5            the page's own options, as given
//
// The address is anyone's to write, so nothing in it is trusted: a name counts only as an own property of a
// schema (never `in`, which finds `constructor` or `__proto__` on every object), no name of a prototype member
// is taken even where a table's names are free, and every value is checked against the same schemas as the
// messages it becomes (protocol.js, messages.js) before it is used: a bad one is left out and named in the one
// notice the page shows. The token never goes in it: `takeToken` takes it out of the query or the fragment at
// once (main.js keeps it for this tab only).

import { CLIENT, PAINT } from "./protocol.js";
import { checkValue, message, valueSchema } from "./messages.js";

const SETTINGS = PAINT.properties;
const OWN = PAINT.$defs.OwnPaintModel.properties;
const PER = ["objects", "materials"];
const SWITCHES = ["temporal", "animate", "collide", "gravity"];
const CAMERA = ["eye", "look_at", "fov", "projection", "heading"];
const PAGE = ["width", "height", "quality", "resolution"];
export const RESOLUTIONS = [1, 0.75, 0.5, 0.333]; // the page's painting size, as fractions of the window's
const TOKEN = "token";
const round = (x) => Math.round(x * 1e5) / 1e5;

/** Names no table of the page takes: those of the members every object inherits. */
const PROTOTYPE_NAMES = new Set([...Object.getOwnPropertyNames(Object.prototype), "prototype"]);

/** Whether `name` is one of `table`'s own names (and names no prototype member). */
export function owns(table, name) {
  return !PROTOTYPE_NAMES.has(name) && Object.hasOwn(table, name);
}

/**
 * The token of an address (the query's `token` or the fragment's), and the address without it: the page puts
 * the latter in place at once (history.replaceState), so no link, bookmark or Referer carries it.
 * @param {string} href
 * @returns {{token: string | null, address: string}}
 */
export function takeToken(href) {
  const url = new URL(href);
  const fragment = new URLSearchParams(url.hash.slice(1));
  const given = url.searchParams.has(TOKEN) || fragment.has(TOKEN);
  if (!given) return { token: null, address: url.pathname + url.search + url.hash }; // as it is, to the letter
  const token = url.searchParams.get(TOKEN) || fragment.get(TOKEN) || null;
  url.searchParams.delete(TOKEN);
  fragment.delete(TOKEN);
  url.hash = fragment.toString();
  return { token, address: url.pathname + url.search.replace(/%2C/g, ",") + url.hash };
}

/** The query string of a view: {scene, camera {eye, look_at, fov}, projection, heading, switches, paint, page}. */
export function encode(view) {
  const query = new URLSearchParams();
  query.set("scene", view.scene);
  if (view.camera) {
    query.set("eye", view.camera.eye.join(","));
    query.set("look_at", view.camera.look_at.join(","));
    query.set("fov", String(view.camera.fov));
  }
  if (view.projection === "equirect") {
    query.set("projection", "equirect");
    query.set("heading", String(round(view.heading ?? 0)));
  }
  for (const [name, on] of Object.entries(view.switches ?? {})) if (on !== undefined) query.set(name, on ? "1" : "0");
  for (const name of Object.keys(view.paint ?? {}).sort()) {
    const value = view.paint[name];
    if (value === null || value === undefined) continue;
    query.set(name, typeof value === "object" ? JSON.stringify(value) : String(value));
  }
  for (const [name, value] of Object.entries(view.page ?? {})) if (value !== undefined && value !== null) query.set(name, String(value));
  return query.toString().replace(/%2C/g, ","); // commas read better, and URLSearchParams takes them back
}

function numbers(text, count) {
  const parts = text.split(",");
  if (parts.length !== count || parts.some((p) => p.trim() === "")) return null;
  const values = parts.map(Number);
  return values.every(Number.isFinite) ? values : null;
}

/** A query value as the paint schema's `schema` takes it: [value] or [undefined, why]. */
function parsed(schema, text) {
  const kind = valueSchema(schema);
  if (kind.type === "number" || kind.type === "integer") {
    const value = text.trim() === "" ? NaN : Number(text);
    return Number.isFinite(value) ? [value] : [undefined, "must be a number"];
  }
  if (kind.type === "boolean") {
    if (text === "true" || text === "1") return [true];
    if (text === "false" || text === "0") return [false];
    return [undefined, "must be true or false"];
  }
  if (kind.type === "object" || kind.additionalProperties) {
    try {
      return [JSON.parse(text)];
    } catch {
      return [undefined, "must be JSON"];
    }
  }
  return [text];
}

/** Why a table of settings per object or material is not one (null: it is). */
function ownProblem(table) {
  if (typeof table !== "object" || table === null || Array.isArray(table)) return "must be a table of names";
  for (const [name, settings] of Object.entries(table)) {
    if (PROTOTYPE_NAMES.has(name)) return `'${name}' names no object`;
    if (typeof settings !== "object" || settings === null || Array.isArray(settings)) return `${name} must be a table`;
    for (const [field, value] of Object.entries(settings)) {
      if (!owns(OWN, field)) return `${name} has no setting '${field}'`;
      const problem = checkValue(OWN[field], value);
      if (problem) return `${name}.${field} ${problem}`;
    }
  }
  return null;
}

/** The page's own options: width and height (a fixed painting size), quality and resolution, each checked. */
function pageOptions(query, problems) {
  const page = {};
  const bounds = { width: CLIENT.hello.properties.width, height: CLIENT.hello.properties.height, quality: CLIENT.hello.properties.quality };
  for (const name of ["width", "height", "quality"]) {
    const text = query.get(name);
    if (text === null) continue;
    const value = text.trim() === "" ? NaN : Number(text);
    const problem = checkValue(bounds[name], value);
    if (problem) problems.push(`${name} ${problem}`);
    else page[name] = value;
  }
  const [width, height] = [page.width !== undefined, page.height !== undefined];
  if (width !== height) {
    // one alone means nothing: the window's size is used (a bad other one has said so already)
    if (!query.has(width ? "height" : "width")) problems.push("width and height go together");
    delete page.width;
    delete page.height;
  }
  if (query.has("resolution")) {
    const value = Number(query.get("resolution"));
    if (RESOLUTIONS.includes(value)) page.resolution = value;
    else problems.push(`resolution must be one of ${RESOLUTIONS.join(", ")}`);
  }
  return page;
}

/**
 * The view of a query string: {scene, camera, projection, heading, switches, paint, page, problems}. A value
 * that would not pass as a message is left out, its problem kept (one line each) for the page's one notice;
 * `pageProblems` are those of the page's own options, which hold whatever the scene.
 */
export function decode(search) {
  const query = new URLSearchParams(search);
  const problems = [];
  const pageProblems = [];
  const scene = query.get("scene");
  const view = { scene, camera: null, projection: null, heading: null, switches: {}, paint: {}, page: {}, problems, pageProblems };
  view.page = pageOptions(query, pageProblems);

  // ---- the camera ----
  if (query.has("eye") || query.has("look_at")) {
    const eye = numbers(query.get("eye") ?? "", 3);
    const lookAt = numbers(query.get("look_at") ?? "", 3);
    const fov = query.has("fov") ? Number(query.get("fov")) : 60;
    if (!eye) problems.push("eye must be three numbers x,y,z");
    else if (!lookAt) problems.push("look_at must be three numbers x,y,z");
    else if (eye.every((x, k) => x === lookAt[k])) problems.push("look_at must differ from eye");
    else {
      try {
        const camera = { eye, look_at: lookAt, up: [0, 1, 0], fov };
        message("camera", camera); // the same checks as the camera message it becomes
        view.camera = camera;
      } catch (error) {
        problems.push(error.message.replace(/^camera\./, ""));
      }
    }
  }
  if (query.has("projection")) {
    const projection = query.get("projection");
    const heading = Number(query.get("heading") ?? 0);
    if (projection !== "equirect" && projection !== "perspective") problems.push("projection must be perspective or equirect");
    else if (!Number.isFinite(heading)) problems.push("heading must be a number");
    else [view.projection, view.heading] = [projection, heading];
  }

  // ---- switches ----
  for (const name of SWITCHES) {
    if (!query.has(name)) continue;
    const text = query.get(name);
    if (["1", "true"].includes(text)) view.switches[name] = true;
    else if (["0", "false"].includes(text)) view.switches[name] = false;
    else problems.push(`${name} must be 0 or 1`);
  }

  // ---- painting settings ----
  for (const [name, text] of query.entries()) {
    if (name === "scene" || name === TOKEN || CAMERA.includes(name) || SWITCHES.includes(name) || PAGE.includes(name)) continue;
    if (!owns(SETTINGS, name) || name === "type") {
      problems.push(`'${name.slice(0, 40)}' is no setting`);
      continue;
    }
    const [value, why] = parsed(SETTINGS[name], text);
    const problem = why ?? checkValue(SETTINGS[name], value) ?? (PER.includes(name) ? ownProblem(value) : null);
    if (problem) problems.push(`${name} ${problem}`);
    else view.paint[name] = value;
  }
  try {
    message("paint", view.paint);
  } catch (error) {
    problems.push(error.message);
    view.paint = {};
  }
  return view;
}

/** The one notice for a link's problems (null when it has none). */
export function linkNotice(problems) {
  if (!problems.length) return null;
  return `This link's ${problems.join("; ")}: left out`;
}
