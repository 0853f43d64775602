// @ts-check
// Settings per object and per material. A click on the view (a press without a drag) asks the server what that
// pixel shows (`pick`, answered by `picked`); the section then offers the settings an object or a material may
// take (the OwnPaintModel schema of protocol.js: every field, with its range and choices) for it, and lists
// every override, each removable. Overrides travel as the `objects` and `materials` of a paint message.

import { PAINT } from "./protocol.js";
import { checkValue, valueSchema } from "./messages.js";

const OWN = PAINT.$defs.OwnPaintModel.properties;
const FIRST = ["mapping", "lambda_p", "eye_mapping", "lambda_e"]; // the rest follow in the schema's order
const FIELDS = [...FIRST.filter((n) => Object.hasOwn(OWN, n)), ...Object.keys(OWN).filter((n) => !FIRST.includes(n))];

function element(tag, attributes = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attributes)) {
    if (key === "text") node.textContent = value;
    else node.setAttribute(key, value);
  }
  node.append(...children);
  return node;
}

/** A control for one setting of OwnPaintModel: a choice, a switch or a number box. */
function control(name, onValue) {
  const schema = valueSchema(OWN[name]);
  let input;
  if (schema.enum) {
    input = element("select", { id: `own-${name}` }, element("option", { value: "", text: "—" }));
    for (const choice of schema.enum) input.append(element("option", { value: choice, text: choice }));
    input.addEventListener("change", () => input.value && onValue(input.value));
  } else if (schema.type === "boolean") {
    input = element("input", { type: "checkbox", id: `own-${name}`, class: "switch" });
    input.addEventListener("change", () => onValue(input.checked));
  } else {
    input = element("input", { type: "number", step: "any", class: "num", id: `own-${name}` });
    input.addEventListener("change", () => {
      const value = Number(input.value);
      const problem = input.value.trim() === "" ? "needs a value" : checkValue(schema, value);
      input.classList.toggle("invalid", Boolean(problem));
      input.title = problem ? `${name} ${problem}` : "";
      if (!problem) onValue(value);
    });
  }
  return element("div", { class: "row", "data-own": name }, element("label", { for: `own-${name}`, text: name.replace(/_/g, " ") }), input);
}

/**
 * The section in `container`. `onChange(per, table)` gets the whole table of `per` ("objects" or "materials")
 * after each edit (null: none left). Returns {picked(msg), setScene(paint), show(paint)}.
 */
export function objectsPanel(container, onChange) {
  const tables = { objects: {}, materials: {} }; // the user's
  let scene = { objects: {}, materials: {} }; // the scene's own, listed beneath (the user's merge into them)
  let target = null; // [per, name]: what the controls set
  const info = element("p", { class: "muted small", id: "picked", text: "Click the view to pick an object." });
  const which = element("div", { class: "choices", role: "group", id: "own-target" });
  const controls = element("div", { id: "own-controls", hidden: "" });
  const list = element("ul", { id: "overrides", "aria-label": "Settings per object and material" });
  for (const name of FIELDS) {
    controls.append(
      control(name, (value) => {
        if (!target) return;
        const [per, key] = target;
        // a blur repeats the last change: no new list, or a click on its buttons would land on nothing
        if (tables[per][key]?.[name] === value) return;
        tables[per][key] = { ...(tables[per][key] ?? {}), [name]: value };
        render();
        onChange(per, { ...tables[per] });
      }),
    );
  }
  container.append(info, which, controls, list);

  function aim(per, name) {
    target = [per, name];
    for (const button of which.querySelectorAll("button")) {
      button.setAttribute("aria-pressed", String(button.dataset.per === per));
    }
    controls.hidden = false;
    const own = tables[per][name] ?? {};
    for (const [field, schema] of Object.entries(OWN)) {
      const input = controls.querySelector(`#own-${field}`);
      const value = own[field];
      if (valueSchema(schema).type === "boolean") input.checked = Boolean(value);
      else input.value = value ?? "";
    }
  }

  function render() {
    list.replaceChildren();
    for (const per of ["objects", "materials"]) {
      for (const [name, settings] of Object.entries(tables[per])) {
        const text = `${per === "objects" ? "object" : "material"} ${name}: ${Object.entries(settings)
          .map(([k, v]) => `${k} ${v}`)
          .join(", ")}`;
        const remove = element("button", { type: "button", class: "link", title: "Remove", text: "×" });
        remove.addEventListener("click", () => {
          delete tables[per][name];
          render();
          onChange(per, Object.keys(tables[per]).length ? { ...tables[per] } : null);
        });
        list.append(element("li", { "data-override": `${per}:${name}` }, element("span", { text }), remove));
      }
      for (const [name, settings] of Object.entries(scene[per] ?? {})) {
        const text = `${per === "objects" ? "object" : "material"} ${name}: ${Object.entries(settings)
          .map(([k, v]) => `${k} ${v}`)
          .join(", ")} (the scene's)`;
        list.append(element("li", { "data-scene-override": `${per}:${name}`, class: "muted" }, element("span", { text })));
      }
    }
  }

  return {
    /** The server's answer to a pick: aim the controls at that object (or its material, by the buttons). */
    picked(msg) {
      which.replaceChildren();
      if (msg.object === null) {
        info.textContent = "The sky: it paints with the scene's settings.";
        controls.hidden = true;
        target = null;
        return;
      }
      info.textContent = `Object ${msg.object}${msg.material ? `, material ${msg.material}` : ""}: its own settings`;
      const options = [["objects", msg.object]];
      if (msg.material) options.push(["materials", msg.material]);
      for (const [per, name] of options) {
        const button = element("button", { type: "button", "data-per": per, text: `${per === "objects" ? "object" : "material"} ${name}` });
        button.addEventListener("click", () => aim(per, name));
        which.append(button);
      }
      aim("objects", msg.object);
    },
    /** The scene's own settings per object and material (its `paint`), listed beneath the user's. */
    setScene(paint) {
      scene = { objects: paint.objects ?? {}, materials: paint.materials ?? {} };
      render();
    },
    /** Show the overrides of `paint` (the user's settings: objects and materials among them). */
    show(paint) {
      tables.objects = { ...(paint.objects ?? {}) };
      tables.materials = { ...(paint.materials ?? {}) };
      render();
    },
  };
}
