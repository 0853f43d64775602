// @ts-check
// Styles and presets: the server's named looks (GET /api/styles) in a picker, and the user's own presets,
// kept in this browser (localStorage): save the current painting settings under a name, apply, delete.
//
// A preset is what the client sends as `paint` (a style and the settings changed beside it). Presets are
// checked against the paint schema of protocol.js when read back, so one saved by an older client, or
// edited by hand, loses only the settings this server no longer takes.

import { PAINT } from "./protocol.js";
import { checkValue } from "./messages.js";

const STORE = "rcp.presets";
/** @param {string} id @returns {any} */
const $ = (id) => document.getElementById(id);

/** The settings of `settings` that the paint schema takes (name -> value); others are dropped. */
function valid(settings) {
  const properties = PAINT.properties;
  const kept = Object.entries(settings ?? {}).filter(
    ([name, value]) => Object.hasOwn(properties, name) && value !== null && checkValue(properties[name], value) === null,
  );
  return Object.fromEntries(kept);
}

/** The saved presets, name -> settings (an unreadable store reads as none). */
export function loadPresets() {
  try {
    const stored = JSON.parse(localStorage.getItem(STORE) ?? "{}");
    if (typeof stored !== "object" || stored === null || Array.isArray(stored)) return {};
    return Object.fromEntries(Object.entries(stored).map(([name, settings]) => [name, valid(settings)]));
  } catch {
    return {};
  }
}

function storePresets(presets) {
  try {
    localStorage.setItem(STORE, JSON.stringify(presets));
    return true;
  } catch {
    return false; // storage full or refused (private browsing): the preset lives until the page closes
  }
}

/**
 * The Style section of the panel. `styles`: the server's StyleInfo list; `current()`: the settings in use
 * (what `paint` sends); `apply(settings)`: replace them. Returns {show(styleName)} to follow changes made
 * elsewhere (a reset).
 */
export function stylesPanel(styles, { current, apply, notice }) {
  const select = $("style");
  const info = $("style-info");
  const list = $("presets");
  const byName = Object.fromEntries(styles.map((s) => [s.name, s]));
  let presets = loadPresets();

  for (const style of styles) select.append(new Option(style.title, style.name));

  function show(name) {
    select.value = name ?? "";
    info.textContent = name ? byName[name]?.description ?? "" : "the scene's own painting";
  }

  select.addEventListener("change", () => {
    select.blur(); // keys walk again
    const name = select.value || null;
    apply(name ? { style: name } : {}); // a style starts from its own settings, not the ones changed before
    show(name);
  });

  function renderPresets() {
    list.replaceChildren();
    for (const name of Object.keys(presets).sort()) {
      const use = document.createElement("button");
      use.type = "button";
      use.className = "preset-apply";
      use.textContent = name;
      use.title = JSON.stringify(presets[name]);
      use.addEventListener("click", () => {
        apply({ ...presets[name] });
        show(presets[name].style);
      });
      const remove = document.createElement("button");
      remove.type = "button";
      remove.className = "preset-delete";
      remove.textContent = "✕";
      remove.title = `Delete the preset '${name}'`;
      remove.addEventListener("click", () => {
        delete presets[name];
        storePresets(presets);
        renderPresets();
      });
      const item = document.createElement("li");
      item.dataset.preset = name;
      item.append(use, remove);
      list.append(item);
    }
  }

  $("preset-save").addEventListener("click", () => {
    const input = $("preset-name");
    const name = input.value.trim().slice(0, 40);
    if (!name) return notice("name the preset first", "info");
    presets = { ...loadPresets(), [name]: valid(current()) }; // another tab may have saved some meanwhile
    if (!storePresets(presets)) notice("this browser does not keep presets: it is kept until the page closes");
    input.value = "";
    input.blur();
    renderPresets();
  });

  renderPresets();
  show(null);
  return { show };
}
