// @ts-check
// The path's keyframes on a timeline: a marker a key at its time, dragged to retime it (between its
// neighbours), clicked to select it; and a scrub bar under them whose time the walk view shows.

const GAP = 0.01; // seconds a retimed key keeps from its neighbours (the server takes 1 ms and more)

/**
 * A timeline in `root` (created inside it). `hooks`: keys() -> the keyframes; selected() -> the selected
 * index or -1; select(index); retime(index, t) once a drag ends; scrub(t) as the scrub bar moves.
 */
export function timeline(root, hooks) {
  const track = document.createElement("div");
  track.className = "timeline";
  track.dataset.path = "timeline";
  const scrub = document.createElement("input");
  Object.assign(scrub, { type: "range", min: 0, max: 1, step: 0.01, value: 0, title: "Scrub: the view at this time" });
  scrub.dataset.path = "scrub";
  scrub.className = "wide";
  root.append(track, scrub);
  let drag = null; // {index, marker}

  const end = () => Math.max(1, hooks.keys().at(-1)?.t ?? 1);
  const left = (t) => `${(100 * t) / end()}%`;
  const timeAt = (x) => {
    const box = track.getBoundingClientRect();
    return Math.max(0, ((x - box.left) / Math.max(box.width, 1)) * end());
  };

  function draw() {
    track.replaceChildren();
    hooks.keys().forEach((key, index) => {
      const marker = document.createElement("button");
      Object.assign(marker, { type: "button", title: `keyframe ${index + 1} at ${key.t} s` });
      marker.className = `key${index === hooks.selected() ? " selected" : ""}`;
      marker.dataset.index = index;
      marker.style.left = left(key.t);
      marker.addEventListener("pointerdown", (event) => {
        event.preventDefault();
        hooks.select(index);
        drag = { index, marker: track.querySelector(`[data-index="${index}"]`), t: key.t };
        drag.marker?.setPointerCapture?.(event.pointerId);
      });
      track.append(marker);
    });
    scrub.max = String(end());
  }

  track.addEventListener("pointermove", (event) => {
    if (!drag) return;
    const keys = hooks.keys();
    const before = keys[drag.index - 1]?.t ?? -Infinity;
    const after = keys[drag.index + 1]?.t ?? Infinity;
    drag.t = Math.round(Math.min(Math.max(timeAt(event.clientX), before + GAP, 0), after - GAP) * 100) / 100;
    drag.marker.style.left = left(drag.t);
  });
  const drop = () => {
    if (!drag) return;
    const { index, t } = drag;
    drag = null;
    if (t !== hooks.keys()[index]?.t) hooks.retime(index, t);
  };
  track.addEventListener("pointerup", drop);
  track.addEventListener("pointercancel", drop);
  scrub.addEventListener("input", () => hooks.scrub(Number(scrub.value)));
  return { draw, scrub };
}
