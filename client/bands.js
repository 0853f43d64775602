// @ts-check
// A frame painted in bands on several machines arrives as its `frame` message (with `bands`: each band's
// [first row, rows], top to bottom) and one JPEG per band, forwarded by the server as the workers encoded them.
// The bands are gathered here, each drawn in place at its rows, and the frame is shown once all are in.

/** Gathers a frame's binary messages: one JPEG, or one per band. */
export class FrameParts {
  constructor() {
    this.meta = null; // the frame whose JPEGs are on their way
    this.parts = [];
  }

  /** A `frame` message: its JPEGs follow. */
  expect(meta) {
    this.meta = meta;
    this.parts = [];
  }

  /**
   * A binary message: the frame's meta and its JPEG (or its bands' JPEGs, an array) once all are in, else null.
   * @param {ArrayBuffer} data
   * @returns {[object, ArrayBuffer | ArrayBuffer[]] | null}
   */
  take(data) {
    const meta = this.meta;
    if (!meta) return null;
    if (!meta.bands) {
      this.meta = null;
      return [meta, data];
    }
    this.parts.push(data);
    if (this.parts.length < meta.bands.length) return null;
    const parts = this.parts;
    this.meta = null;
    this.parts = [];
    return [meta, parts];
  }
}

/**
 * The picture of a frame: its JPEG decoded, or its bands' decoded and drawn at their rows.
 * @param {object} meta                        the `frame` message
 * @param {ArrayBuffer | ArrayBuffer[]} jpeg   the JPEG, or one per band (top to bottom)
 * @returns {Promise<ImageBitmap>}
 */
export async function decodeFrame(meta, jpeg) {
  if (!Array.isArray(jpeg)) return createImageBitmap(new Blob([jpeg], { type: "image/jpeg" }));
  const bands = await Promise.all(jpeg.map((part) => createImageBitmap(new Blob([part], { type: "image/jpeg" }))));
  const canvas = new OffscreenCanvas(meta.width, meta.height);
  const context = canvas.getContext("2d");
  bands.forEach((band, k) => {
    context.drawImage(band, 0, meta.bands[k][0]);
    band.close();
  });
  return createImageBitmap(canvas);
}
