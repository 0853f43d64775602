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
// The token never goes in it (it stays in the fragment's place: sessionStorage, main.js). Values are checked
// against the same schemas as the messages they become (protocol.js, messages.js): a bad one is left out and
// named in the one notice the page shows.

import { PAINT } from "./protocol.js";
import { checkValue, message, valueSchema } from "./messages.js";

const SETTINGS = PAINT.properties;
const OWN = PAINT.$defs.OwnPaintModel.properties;
const PER = ["objects", "materials"];
const SWITCHES = ["temporal", "animate", "collide", "gravity"];
const CAMERA = ["eye", "look_at", "fov", "projection", "heading"];
export const PAGE = ["width", "height", "quality", "resolution"]; // read by main.js as ever
const round = (x) => Math.round(x * 1e5) / 1e5;

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
    if (typeof settings !== "object" || settings === null || Array.isArray(settings)) return `${name} must be a table`;
    for (const [field, value] of Object.entries(settings)) {
      if (!(field in OWN)) return `${name} has no setting '${field}'`;
      const problem = checkValue(OWN[field], value);
      if (problem) return `${name}.${field} ${problem}`;
    }
  }
  return null;
}

/**
 * The view of a query string: {scene, camera, projection, heading, switches, paint, problems}. A value that
 * would not pass as a message is left out, its problem kept (one line each) for the page's one notice.
 */
export function decode(search) {
  const query = new URLSearchParams(search);
  const problems = [];
  const view = { scene: query.get("scene"), camera: null, projection: null, heading: null, switches: {}, paint: {}, problems };

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
    if (name === "scene" || CAMERA.includes(name) || SWITCHES.includes(name) || PAGE.includes(name)) continue;
    if (!(name in SETTINGS) || name === "type") {
      problems.push(`'${name}' is no setting`);
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
