// @ts-check
// The film's kind and size: flat or 360° (equirect: every keyframe's camera becomes a panorama at its eye, as
// the 360° view shows), at a size chosen from a list, the view's own first.

const SIZES = {
  perspective: [[640, 360], [1280, 720], [1920, 1080]],
  equirect: [[1024, 512], [2048, 1024], [3840, 1920]],
};
const even = (/** @type {number} */ n) => n - (n % 2); // H.264 in yuv420p takes even sizes

export class FilmSize {
  /**
   * `film` and `size` are the panel's selects; `viewSize(film)` -> the view's painting size as that film takes it.
   * @param {HTMLSelectElement} film @param {HTMLSelectElement} size
   * @param {(film: string) => number[]} viewSize
   */
  constructor(film, size, viewSize) {
    this.film = film;
    this.size = size;
    this.viewSize = viewSize;
  }

  /** The list of sizes again (the view's may have changed), keeping the one chosen. */
  show() {
    const chosen = this.size.value;
    const film = this.film.value;
    const [width, height] = this.viewSize(film);
    this.size.replaceChildren(new Option(`the view's (${even(width)}×${even(height)})`, "view"));
    for (const [w, h] of SIZES[film]) this.size.append(new Option(`${w}×${h}`, `${w}x${h}`));
    this.size.value = [...this.size.options].some((o) => o.value === chosen) ? chosen : "view";
  }

  /** The film's [width, height] in pixels. */
  chosen() {
    const chosen = this.size.value;
    const [width, height] = chosen === "view" || !chosen ? this.viewSize(this.film.value) : chosen.split("x").map(Number);
    return [even(width), even(height)];
  }

  /** @param {string} kind "perspective" or "equirect" */
  set(kind) {
    this.film.value = kind;
    this.show();
  }
}
