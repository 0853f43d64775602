// @ts-check
// The path saved and loaded as the JSON that `rcp render --path` and POST /api/videos read.

/**
 * Download `spec` (a path as the CLI takes it) as `name`.
 * @param {any} spec @param {string} name
 */
export function savePath(spec, name) {
  const link = document.createElement("a");
  link.href = URL.createObjectURL(new Blob([JSON.stringify(spec, null, 1)], { type: "application/json" }));
  link.download = name;
  link.click();
  setTimeout(() => URL.revokeObjectURL(link.href), 30000);
}

/**
 * The path in `file`: {keyframes (copies), fps, loop, film ("equirect" if a keyframe is a panorama)}; throws
 * an Error saying why it cannot be one.
 * @param {File} file
 */
export async function readPath(file) {
  const loaded = JSON.parse(await file.text());
  if (!Array.isArray(loaded?.keyframes)) throw new Error("no keyframes in it");
  const keyframes = loaded.keyframes.map((k) => ({ ...k }));
  const film = keyframes.some((k) => k.projection === "equirect") ? "equirect" : "perspective";
  return { keyframes, fps: loaded.fps ?? 24, loop: Boolean(loaded.loop), film };
}
