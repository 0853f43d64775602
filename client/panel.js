// @ts-check
// The painting controls, built from the PaintModel schema of protocol.js: every field the server takes gets
// a control, with the server's range and choices. PAINT_UI only adds words and a comfortable slider range;
// a field the server adds later still appears (under "More"), with a generic control.

import { PAINT } from "./protocol.js";
import { checkValue, valueSchema } from "./messages.js";

// label, unit, the slider's range (the number box takes the server's whole range), step, log slider
const PAINT_UI = {
  mapping: { label: "Mapping", hint: "what moves each pixel's camera target" },
  method: { label: "Method", hint: "ray-traced, or the image-space shortcut" },
  iterations: { label: "Iterations", slider: [1, 24], step: 1 },
  // `fit`: the slider spans four times the scene's value either way (a depth mapping's lambda_p is per unit
  // of depth, often below 1; a color mapping's is in pixels, often above 10)
  lambda_p: { label: "λp smudge", unit: "px", slider: [-64, 64], fit: true },
  lambda_e: { label: "λe eye move", unit: "units", slider: [-2, 2], fit: true },
  z0: { label: "Focus depth z0", unit: "units", slider: [0.1, 1000], log: true },
  spp: { label: "Samples / pixel", slider: [1, 16], step: 1 },
  eye_mapping: { label: "Eye mapping", more: true },
  noise: { label: "Screen noise", slider: [0, 4], step: 0.05, more: true },
  surface_noise: { label: "Surface noise", slider: [0, 4], step: 0.05, more: true },
  surface_scale: { label: "Surface noise × smudge", slider: [0, 4], step: 0.05, more: true },
  grain: { label: "Surface noise grain", unit: "units", slider: [0.001, 10], log: true, more: true },
  hatch: { label: "Hatch lines", more: true },
  seed: { label: "Seed", slider: [0, 99], step: 1, more: true },
  z_max: { label: "Miss depth z_max", unit: "units", slider: [1, 10000], log: true, more: true },
  edge: { label: "Edge (image method)", more: true },
};

const LOG_STEPS = 1000;

function title(name) {
  return name.replace(/_/g, " ").replace(/^./, (c) => c.toUpperCase());
}

/** Three significant digits: slider values a person can read. */
function tidy(value) {
  if (value === 0) return 0;
  const digits = Math.max(0, 2 - Math.floor(Math.log10(Math.abs(value))));
  return Number(value.toFixed(Math.min(digits, 6)));
}

function element(tag, attributes = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attributes)) {
    if (key === "class") node.className = value;
    else if (key === "text") node.textContent = value;
    else node.setAttribute(key, value);
  }
  node.append(...children);
  return node;
}

/** A row of segmented buttons for a field with a few choices. */
function choiceControl(name, schema, emit) {
  const group = element("div", { class: "choices", role: "group", id: `paint-${name}` });
  const buttons = schema.enum.map((choice) => {
    const button = element("button", { type: "button", "data-value": choice, text: choice });
    button.addEventListener("click", () => emit(choice));
    group.append(button);
    return button;
  });
  return {
    input: group,
    show(value) {
      for (const button of buttons) button.setAttribute("aria-pressed", String(button.dataset.value === value));
    },
  };
}

/** A switch for a true/false field. */
function switchControl(name, emit) {
  const box = element("input", { type: "checkbox", class: "switch", id: `paint-${name}` });
  box.addEventListener("change", () => emit(box.checked));
  return {
    input: box,
    show(value) {
      box.checked = Boolean(value);
    },
  };
}

/** A number box (the server's whole range) above a slider (a comfortable range, linear or logarithmic). */
function numberControl(name, schema, ui, emit) {
  const integer = schema.type === "integer";
  const low = schema.minimum ?? schema.exclusiveMinimum ?? 0;
  const high = schema.maximum ?? schema.exclusiveMaximum ?? 100;
  const [smin, smax] = ui.slider ?? [low, high];
  let [sliderMin, sliderMax] = [Math.max(smin, low), Math.min(smax, high)];
  const step = ui.step ?? (integer ? 1 : "any");
  const box = element("input", { type: "number", class: "num", id: `paint-${name}`, step: String(step) });
  if (schema.minimum !== undefined) box.min = schema.minimum;
  if (schema.maximum !== undefined) box.max = schema.maximum;
  const slider = element("input", { type: "range", class: "slider", "aria-label": ui.label ?? title(name) });
  if (ui.log) Object.assign(slider, { min: 0, max: LOG_STEPS, step: 1 });
  else Object.assign(slider, { min: sliderMin, max: sliderMax, step });

  const toSlider = (v) =>
    ui.log ? (LOG_STEPS * Math.log(v / sliderMin)) / Math.log(sliderMax / sliderMin) : Math.min(sliderMax, Math.max(sliderMin, v));
  const fromSlider = (p) => tidy(ui.log ? sliderMin * (sliderMax / sliderMin) ** (p / LOG_STEPS) : Number(p));

  slider.addEventListener("input", () => {
    const value = fromSlider(slider.value);
    box.value = value;
    box.classList.remove("invalid");
    emit(integer ? Math.round(value) : value);
  });
  box.addEventListener("change", () => {
    const value = Number(box.value);
    const problem = box.value.trim() === "" ? "needs a value" : checkValue(schema, value);
    box.classList.toggle("invalid", Boolean(problem));
    box.title = problem ? `${ui.label ?? title(name)} ${problem}` : "";
    if (!problem) {
      slider.value = toSlider(value);
      emit(value);
    }
  });
  return {
    input: box,
    slider,
    /** The scene's value: a `fit` slider spans four times it either way. */
    fit(value) {
      if (!ui.fit) return;
      const span = value ? 4 * Math.abs(value) : smax; // a scene's 0 says nothing about scale
      [sliderMin, sliderMax] = [Math.max(-span, low), Math.min(span, high)];
      Object.assign(slider, { min: sliderMin, max: sliderMax });
    },
    show(value) {
      box.classList.remove("invalid");
      box.value = value ?? "";
      box.placeholder = value === undefined || value === null ? "auto" : "";
      if (value !== undefined && value !== null) slider.value = toSlider(value);
    },
  };
}

/**
 * The painting panel in `container`. `onChange(name, value)` gets each edit (value null: back to the
 * scene's default). Returns {setScene(defaults), show(overrides), fields}.
 */
export function paintPanel(container, onChange) {
  const properties = PAINT.properties;
  const names = [...Object.keys(PAINT_UI).filter((n) => Object.hasOwn(properties, n)), ...Object.keys(properties).filter((n) => !Object.hasOwn(PAINT_UI, n))]
    .filter((n) => !["style", "objects", "materials"].includes(n)); // the style has its own picker (styles.js),
  // the settings per object and material theirs (objects.js)
  const more = element("details", { class: "more" }, element("summary", { text: "More painting settings" }));
  const controls = {};
  let defaults = {};
  let overrides = {};

  for (const name of names) {
    const schema = valueSchema(properties[name]);
    const ui = PAINT_UI[name] ?? { more: true };
    const emit = (value) => {
      overrides[name] = value;
      render(name);
      onChange(name, value);
    };
    const control = schema.enum
      ? choiceControl(name, schema, emit)
      : schema.type === "boolean"
        ? switchControl(name, emit)
        : numberControl(name, schema, ui, emit);
    const reset = element("button", { type: "button", class: "reset", title: "Back to the scene's value", text: "↺" });
    reset.addEventListener("click", () => {
      delete overrides[name];
      render(name);
      onChange(name, null);
    });
    const label = element("label", { for: `paint-${name}`, text: ui.label ?? title(name) });
    if (ui.unit) label.append(element("span", { class: "unit", text: ` ${ui.unit}` }));
    const hint = ui.hint ?? properties[name].description; // the server's help text, unless we say it better
    if (hint) label.title = hint;
    const row = element("div", { class: "row", "data-field": name }, label, control.input, reset);
    if (control.slider) row.append(control.slider);
    (ui.more ? more : container).append(row);
    controls[name] = { control, row };
  }
  container.append(more);

  function render(name) {
    const { control, row } = controls[name];
    const changed = Object.hasOwn(overrides, name);
    row.classList.toggle("changed", changed);
    control.show(changed ? overrides[name] : defaults[name]);
  }

  return {
    fields: names,
    /** The scene's painting defaults (engine defaults filled in); the user's changes are cleared. */
    setScene(sceneDefaults) {
      defaults = { ...sceneDefaults };
      overrides = {};
      for (const name of names) controls[name].control.fit?.(defaults[name]);
      names.forEach(render);
    },
    /** Show the user's changes (name -> value). */
    show(changes) {
      overrides = { ...changes };
      names.forEach(render);
    },
  };
}
