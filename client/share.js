// @ts-check
// Share links: the page's address always carries the view it shows (link.js writes and reads it), kept up to
// date a few times a second, and Copy link puts it on the clipboard. It never carries the token.

import * as walkCamera from "./camera.js";
import { encode } from "./link.js";

/**
 * The page's own options: the fixed size its address gave (checked), the quality and Resolution as chosen.
 * @param {any} page  state, link
 */
export function pageOptions(page) {
  const { state, link } = page;
  /** @type {Object<string, number>} */
  const options = {};
  if (link.page.width !== undefined) Object.assign(options, { width: link.page.width, height: link.page.height });
  if (state.quality !== 80) options.quality = state.quality;
  if (state.resolution !== 1) options.resolution = state.resolution;
  return options;
}

/**
 * The address of the view shown: scene, camera, 360° view, switches, painting; never the token.
 * @param {any} page  state, walk, view360, link
 */
export function shareLink(page) {
  const { state, walk, view360 } = page;
  if (!state.scene || !walk.walk) return location.origin + location.pathname + location.search;
  const view = {
    scene: state.scene.name,
    camera: walkCamera.toCamera(walk.walk),
    projection: view360.active ? "equirect" : null,
    heading: view360.yaw0,
    switches: {
      temporal: state.temporal || undefined,
      animate: state.animate || undefined,
      collide: state.collide ? undefined : false,
      gravity: state.gravity || undefined,
    },
    paint: state.paint,
    page: pageOptions(page),
  };
  return `${location.origin}${location.pathname}?${encode(view)}`;
}

/**
 * Keeps the address up to date; called a few times a second (replaceState is not for every frame).
 * @param {any} page
 */
export function addressKeeper(page) {
  let shown = "";
  return () => {
    if (!page.state.scene || page.link.scene) return; // the link's own view is not applied yet
    const address = shareLink(page);
    if (address === shown) return;
    shown = address;
    history.replaceState(null, "", address);
  };
}

/**
 * Copy link: on the clipboard, or, where the page may not write it, selected in a box for the user to copy.
 * @param {any} page  notice(text, kind)
 * @param {HTMLButtonElement} button
 * @param {HTMLInputElement} box
 */
export async function copyLink(page, button, box) {
  const address = shareLink(page);
  try {
    await navigator.clipboard.writeText(address);
    page.notice("Link copied: it opens this view", "info");
  } catch {
    box.hidden = false;
    box.value = address;
    box.select();
    page.notice("Copy the selected link", "info");
  }
  button.dataset.copied = address;
}
