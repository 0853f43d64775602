// @ts-check
// What the page asks the server for before it walks: the scenes (waiting out a server that is still starting,
// which says how far it is and when to ask again) and the named styles.

/**
 * Every scene (SceneInfo), or null when the server refuses the page (no token): retrying cannot help.
 * @param {Object<string, string>} authorization  the header of the token, if any
 * @param {(text: string) => void} status          the connection's line in the overlay
 * @param {(text: string, kind?: "error" | "info") => void} notice
 * @returns {Promise<import("./protocol.js").SceneInfo[] | null>}
 */
export async function loadScenes(authorization, status, notice) {
  for (let wait = 500; ; wait = Math.min(wait * 2, 8000)) {
    try {
      const response = await fetch("api/scenes", { headers: authorization });
      if (response.ok) return await response.json();
      const starting = await startingFrom(response);
      if (starting) {
        // a first start: the kernels compile (rcp_server/service/startup.py); the server says how far, and when to ask again
        status(starting.text);
        notice(starting.text, "info");
        await new Promise((resolve) => setTimeout(resolve, starting.retryMs));
        continue;
      }
      if (response.status === 401) {
        status("needs a token: open /#token=…");
        notice((await response.json()).detail);
        return null;
      }
    } catch {
      // the server is not up yet: try again
    }
    status("waiting for the server…");
    await new Promise((resolve) => setTimeout(resolve, wait));
  }
}

/**
 * A 503 "starting" answer as {text: "starting: compiling kernels (3/14)", retryMs}, or null for any other.
 * @param {Response} response
 */
async function startingFrom(response) {
  if (response.status !== 503) return null;
  const body = await response.json().catch(() => null);
  if (body?.status !== "starting") return null;
  const count = body.total ? ` (${body.done}/${body.total})` : "";
  const retryMs = 1000 * Math.min(Math.max(Number(response.headers.get("retry-after")) || 1, 0.5), 5);
  return { text: `starting: ${body.phase}${count}`, retryMs };
}

/**
 * The named styles (GET /api/styles); none when they cannot be had.
 * @param {Object<string, string>} authorization
 * @returns {Promise<any[]>}
 */
export async function loadStyles(authorization) {
  try {
    const response = await fetch("api/styles", { headers: authorization });
    if (response.ok) return await response.json();
  } catch {
    // no styles: the picker stays empty, presets still work
  }
  return [];
}
