// @ts-check
// Save: the view shown, painted once more at full size as the server refines a view at rest (the rule `ready`
// gives), through POST /api/render, as a PNG download.

import { MESSAGES } from "./messages.js";

/**
 * The samples per pixel of a view at rest, by the server's rule (protocol.js: RefineRule).
 * @param {import("./protocol.js").RefineRule} rule
 * @param {number} spp  the painting's own
 */
export function refinedSpp(rule, spp) {
  return Math.max(spp, Math.min(rule.most, Math.max(rule.least, rule.times * spp)));
}

/**
 * Paint the view once more and download it.
 * @param {any} page  state, overlay, currentCamera(), authorization, notice(text)
 * @param {HTMLButtonElement} button
 */
export async function save(page, button) {
  const { state } = page;
  if (!state.scene || !state.refine) return;
  const spp = state.paint.spp ?? state.defaults.spp ?? 1;
  const paint = MESSAGES.paint({ ...state.paint, spp: refinedSpp(state.refine, spp) });
  delete paint.type;
  const [width, height] = state.size;
  const body = {
    scene: state.scene.name,
    width,
    height,
    camera: page.currentCamera(), // in the 360° view, the panorama
    paint,
    time: page.overlay.frame?.time ?? 0, // the moment shown, for animated scenes
    format: "png",
  };
  button.disabled = true;
  button.textContent = "Painting…";
  try {
    const response = await fetch("api/render", {
      method: "POST",
      headers: { "content-type": "application/json", ...page.authorization },
      body: JSON.stringify(body),
    });
    if (!response.ok) {
      const detail = (await response.json().catch(() => ({}))).detail;
      throw new Error(typeof detail === "string" ? detail : (detail?.[0]?.msg ?? `HTTP ${response.status}`));
    }
    const link = document.createElement("a");
    link.href = URL.createObjectURL(await response.blob());
    const stamp = new Date().toISOString().slice(0, 19).replace(/[-:]/g, "").replace("T", "-");
    link.download = `rcp-${state.scene.name}-${stamp}.png`;
    link.click();
    setTimeout(() => URL.revokeObjectURL(link.href), 30000);
  } catch (error) {
    page.notice(`Save failed: ${error.message}`);
  } finally {
    button.disabled = false;
    button.textContent = "Save PNG";
  }
}
