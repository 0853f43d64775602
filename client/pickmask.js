// @ts-check
// A pick answers on the view: the picked object's pixels (the server's `picked` mask) are tinted blue and outlined
// in white, in a canvas laid over the painting, which fades out after a moment.

const SHOWN_MS = 1400;
const TINT = [96, 214, 255]; // a cold light blue: seen on the warm and green colours paintings mostly have

export class PickMask {
  /** @param {HTMLCanvasElement} canvas  laid over the view, the same size on screen */
  constructor(canvas) {
    this.canvas = canvas;
    this.timer = 0;
    this.shown = 0; // masks shown (the tests watch it)
    this.pixels = 0; // pixels of the last one
  }

  /** Show `mask` ({width, height, bits: base64 of packed bits, row-major, highest bit first}). */
  show({ width, height, bits }) {
    const bytes = Uint8Array.from(atob(bits), (c) => c.charCodeAt(0));
    const inside = (x, y) => x >= 0 && y >= 0 && x < width && y < height && (bytes[(y * width + x) >> 3] >> (7 - ((y * width + x) & 7))) & 1;
    const image = new ImageData(width, height);
    let count = 0;
    for (let y = 0; y < height; y++) {
      for (let x = 0; x < width; x++) {
        if (!inside(x, y)) continue;
        count += 1;
        const edge = !inside(x - 1, y) || !inside(x + 1, y) || !inside(x, y - 1) || !inside(x, y + 1);
        const k = 4 * (y * width + x);
        image.data.set(edge ? [255, 255, 255, 255] : [...TINT, 110], k);
      }
    }
    Object.assign(this.canvas, { width, height });
    this.canvas.getContext("2d").putImageData(image, 0, 0);
    this.pixels = count;
    this.shown += 1;
    this.canvas.classList.add("shown");
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.canvas.classList.remove("shown"), SHOWN_MS);
  }
}
