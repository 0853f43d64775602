// @ts-check
// The path panel's REST calls: a JSON body in, the JSON answer out, a refusal as an Error of its one line.

/**
 * A caller of the server's REST routes with the page's `authorization` headers.
 * @param {Record<string, string>} authorization
 * @returns {(url: string, method: string, body?: any) => Promise<any>}
 */
export function caller(authorization) {
  return async (url, method, body) => {
    const response = await fetch(url, {
      method,
      headers: { "content-type": "application/json", ...authorization },
      body: body === undefined ? undefined : JSON.stringify(body),
    });
    const answer = await response.json().catch(() => ({}));
    if (!response.ok) {
      const detail = answer.detail;
      const where = Array.isArray(detail) ? `${detail[0]?.loc?.slice(1).join(".")}: ${detail[0]?.msg}` : detail;
      throw new Error(where ?? `HTTP ${response.status}`);
    }
    return answer;
  };
}

/**
 * A button of the panel: `action` on a click, after which the keys walk again.
 * @param {string} text @param {string} title @param {() => void} action
 */
export function button(text, title, action) {
  const b = document.createElement("button");
  Object.assign(b, { type: "button", textContent: text, title });
  b.addEventListener("click", (event) => {
    /** @type {HTMLElement} */ (event.target).blur(); // keys walk again
    action();
  });
  return b;
}
