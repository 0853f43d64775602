// @ts-check
// A model's animated cameras (a glTF's, SceneInfo.motions) taken as the path: the server samples one at the
// path's frame rate (POST /api/paths with {"camera": name}), and its cameras become keyframes, one a frame,
// which the timeline, the editor and Render video then treat as any other path.

/**
 * The chooser in `root`. `hooks`: scene() -> the SceneInfo shown; fps() -> frames a second; call(url, method,
 * body) -> the answer; take(keyframes) replaces the path's (one step to undo); notice(text, kind).
 */
export function motionChooser(root, hooks) {
  const row = document.createElement("div");
  row.className = "row long";
  row.dataset.path = "motions";
  const select = document.createElement("select");
  select.className = "wide";
  select.title = "The model's animated cameras: one becomes the path";
  select.dataset.path = "motion";
  const take = document.createElement("button");
  Object.assign(take, { type: "button", textContent: "Use", title: "Replace the path by this animated camera's" });
  take.dataset.path = "use-motion";
  row.append("Animated camera", select, take);
  root.append(row);

  function draw() {
    const names = hooks.scene()?.motions ?? [];
    row.hidden = names.length === 0;
    const chosen = select.value;
    select.replaceChildren(...names.map((name) => new Option(name, name)));
    if (names.includes(chosen)) select.value = chosen;
  }

  take.addEventListener("click", async () => {
    take.blur();
    const scene = hooks.scene();
    if (!scene || !select.value) return;
    try {
      const body = { scene: scene.name, path: { camera: select.value, fps: hooks.fps() } };
      const answer = await hooks.call("api/paths", "POST", body);
      const round = (x) => Math.round(x * 1e6) / 1e6;
      hooks.take(answer.cameras.map(({ eye, look_at, up, fov }, k) => ({ t: round(k / answer.fps), eye, look_at, up, fov })));
      hooks.notice(`The path is ${select.value}'s: ${answer.cameras.length} keyframes`, "info");
    } catch (error) {
      hooks.notice(`Cannot use ${select.value}: ${error.message}`);
    }
  });
  select.addEventListener("focus", draw); // the scene may have changed since (an upload)
  return { draw };
}
