// @ts-check
// Client -> server messages, built and checked against the generated schemas of protocol.js.
//
// Every message the client sends goes through `message(type, fields)`: an unknown type, an unknown field,
// a missing required field or a value out of range throws here, in the browser, instead of drifting
// silently from rcp_server/service/protocol.py. The named builders below are the only senders.

import { CLIENT } from "./protocol.js";

/** The schema alternatives of a property: `anyOf` (optional fields are `X | null`) or the schema itself. */
function alternatives(schema) {
  return schema.anyOf ?? [schema];
}

function checkOne(schema, value) {
  if ("const" in schema) return value === schema.const ? null : `must be ${JSON.stringify(schema.const)}`;
  if (schema.enum) return schema.enum.includes(value) ? null : `must be one of ${schema.enum.join(", ")}`;
  switch (schema.type) {
    case "null":
      return value === null ? null : "must be null";
    case "boolean":
      return typeof value === "boolean" ? null : "must be true or false";
    case "string":
      if (typeof value !== "string") return "must be text";
      if (schema.minLength !== undefined && value.length < schema.minLength) return "is too short";
      if (schema.maxLength !== undefined && value.length > schema.maxLength) return "is too long";
      return null;
    case "array": {
      if (!Array.isArray(value)) return "must be a list";
      const items = schema.prefixItems ?? [];
      if (schema.minItems !== undefined && value.length < schema.minItems) return "has too few items";
      if (schema.maxItems !== undefined && value.length > schema.maxItems) return "has too many items";
      for (let k = 0; k < value.length; k++) {
        const problem = items[k] ? checkValue(items[k], value[k]) : null;
        if (problem) return `item ${k} ${problem}`;
      }
      return null;
    }
    case "integer":
    case "number":
      if (typeof value !== "number" || !Number.isFinite(value)) return "must be a finite number";
      if (schema.type === "integer" && !Number.isInteger(value)) return "must be a whole number";
      if (schema.minimum !== undefined && value < schema.minimum) return `must be at least ${schema.minimum}`;
      if (schema.maximum !== undefined && value > schema.maximum) return `must be at most ${schema.maximum}`;
      if (schema.exclusiveMinimum !== undefined && value <= schema.exclusiveMinimum)
        return `must be more than ${schema.exclusiveMinimum}`;
      if (schema.exclusiveMaximum !== undefined && value >= schema.exclusiveMaximum)
        return `must be less than ${schema.exclusiveMaximum}`;
      return null;
    default:
      return null;
  }
}

/** Why `value` does not fit the JSON schema `schema` (one line), or null when it fits. */
export function checkValue(schema, value) {
  const problems = alternatives(schema).map((s) => checkOne(s, value));
  return problems.includes(null) ? null : problems.find((p) => p !== "must be null") ?? problems[0];
}

/** The non-null alternative of a property's schema: its type, range and choices. */
export function valueSchema(schema) {
  return alternatives(schema).find((s) => s.type !== "null") ?? schema;
}

/** A client message of `type` with `fields`, checked against CLIENT (protocol.js); throws when it does not fit. */
export function message(type, fields = {}) {
  const schema = Object.hasOwn(CLIENT, type) ? CLIENT[type] : null; // own names only: never `constructor`
  if (!schema) throw new Error(`the protocol has no client message '${type}'`);
  const given = Object.entries(fields).filter(([, value]) => value !== undefined); // undefined: left out
  const msg = { type, ...Object.fromEntries(given) };
  for (const [name, value] of Object.entries(msg)) {
    const property = Object.hasOwn(schema.properties, name) ? schema.properties[name] : null;
    if (!property) throw new Error(`a '${type}' message has no field '${name}'`);
    const problem = checkValue(property, value);
    if (problem) throw new Error(`${type}.${name} ${problem} (got ${JSON.stringify(value)})`);
  }
  for (const name of schema.required ?? []) {
    if (msg[name] === undefined) throw new Error(`a '${type}' message needs '${name}'`);
  }
  return msg;
}

// ---- the builders: one per message the client sends ----

export const MESSAGES = {
  /** Open or switch a walk-through; the server answers `ready` and resets the camera to the scene's. */
  hello: (scene, width, height, quality) => message("hello", { scene, width, height, quality }),
  /** The newest camera (every field it has: a panorama's projection and stereo too); the server echoes `id` as
   * `camera_id` on the frame showing it. */
  camera: (camera, id) => message("camera", { ...camera, id }),
  /** Painting settings that changed; null restores the scene's default. */
  paint: (changes) => message("paint", changes),
  mode: (temporal, animate) => message("mode", { temporal, animate }),
  view: (width, height, quality) => message("view", { width, height, quality }),
  /** What pixel (x, y) of the view shows; the server answers `picked`. */
  pick: (x, y) => message("pick", { x, y }),
  /** Walk the eye from `eye` by `delta` (world units), kept clear of surfaces; the server answers `moved`. */
  move: (id, eye, delta, height) => message("move", { id, eye, delta, height }),
};
