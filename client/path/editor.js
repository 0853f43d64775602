// @ts-check
// The selected keyframe's values, typed: its time, eye, look-at, field of view, ease in and out, and its
// painting (the `paint` table a path file takes, as JSON) with the seconds it fades in over.

/** @type {Array<[string, string, number]>} the key's fields: name, label, how many numbers */
const FIELDS = [
  ["t", "time (s)", 1],
  ["eye", "eye", 3],
  ["look_at", "look at", 3],
  ["fov", "fov (°)", 1],
  ["ease", "ease in, out (0 to 1)", 2],
  ["fade", "fade (s)", 1],
];

/**
 * The editor in `root`. `hooks`: key() -> the selected keyframe or null; change(fields) applies typed
 * values (one step to undo); notice(text).
 */
export function keyEditor(root, hooks) {
  const form = document.createElement("div");
  form.className = "key-editor";
  form.dataset.path = "editor";
  root.append(form);

  function draw() {
    form.replaceChildren();
    const key = hooks.key();
    form.hidden = !key;
    if (!key) return;
    for (const [name, label, count] of FIELDS) {
      const row = document.createElement("label");
      row.className = "row";
      row.append(label);
      const value = key[name] ?? (name === "ease" ? [0, 0] : name === "fade" ? 0 : undefined);
      const values = count === 1 ? [value] : value;
      values.forEach((v, k) => {
        const input = document.createElement("input");
        Object.assign(input, { type: "number", step: "any", value: String(v ?? "") });
        input.className = "num";
        input.dataset.field = count === 1 ? name : `${name}.${k}`;
        input.addEventListener("change", () => typed(name, count, row));
        row.append(input);
      });
      form.append(row);
    }
    const paint = document.createElement("label");
    paint.className = "row long";
    paint.append("painting");
    const text = document.createElement("input");
    Object.assign(text, { type: "text", value: key.paint ? JSON.stringify(key.paint) : "", placeholder: '{"lambda_p": 12}' });
    text.dataset.field = "paint";
    text.className = "wide";
    text.addEventListener("change", () => {
      try {
        const paint = text.value.trim() ? JSON.parse(text.value) : null;
        if (paint !== null && (typeof paint !== "object" || Array.isArray(paint))) throw new Error("not a table");
        hooks.change({ paint });
      } catch (error) {
        hooks.notice(`The painting must be a JSON table of settings: ${error.message}`);
        draw();
      }
    });
    paint.append(text);
    form.append(paint);
  }

  function typed(name, count, row) {
    const numbers = [...row.querySelectorAll("input")].map((input) => Number(input.value));
    if (numbers.some((n) => !Number.isFinite(n))) return draw();
    hooks.change({ [name]: count === 1 ? numbers[0] : numbers });
  }

  return { draw };
}
