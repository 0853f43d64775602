// @ts-check
// The keyframes as a list: each one's time typed in, a button to look from it, one to move it to the current
// view, one to delete it; a click on the row selects it.

import { button } from "./api.js";

/**
 * The list in `list` (an <ol>). `hooks`: keys() -> the keyframes; change(index, fields); remove(index);
 * select(index); look(key) moves the walk there; here() -> a keyframe's fields at the current view.
 * @param {HTMLElement} list
 * @param {{keys: () => any[], change: (i: number, f: any) => void, remove: (i: number) => void,
 *   select: (i: number) => void, look: (key: any) => void, here: () => any}} hooks
 */
export function keyList(list, hooks) {
  function row(key, index) {
    const row = document.createElement("li");
    row.dataset.index = String(index);
    const time = document.createElement("input");
    Object.assign(time, { type: "number", min: 0, step: 0.1, value: key.t, title: "seconds along the path" });
    time.addEventListener("change", () => hooks.change(index, { t: Math.max(0, Number(time.value) || 0) }));
    row.append(time, button("view", "Look from this keyframe", () => hooks.look(key)));
    row.append(button("set", "Move this keyframe to the current view", () => hooks.change(index, hooks.here())));
    row.append(button("×", "Delete this keyframe", () => hooks.remove(index)));
    row.addEventListener("click", (event) => {
      if (event.target === row) hooks.select(index);
    });
    return row;
  }

  function draw() {
    list.replaceChildren(...hooks.keys().map(row));
  }

  return { draw };
}
