// @ts-check
// Painted frames onto the canvas. Each arrives as a JPEG the size of the painting (smaller than the canvas
// while walking) and is drawn scaled to the canvas. Only the newest frame is decoded: one that arrives
// while another decodes replaces any frame still waiting, so a slow browser never falls behind. A frame smaller
// than the canvas is scaled up with its edges kept sharp where WebGL2 allows (upscale.js, the walk quality).

import { decodeFrame } from "./bands.js";
import { Upscaler } from "./upscale.js";

export class FrameView {
  /**
   * @param {HTMLCanvasElement} canvas  its width and height are the painting's full size
   * @param {object} handlers           shown(meta) after a frame is drawn, failed(message)
   */
  constructor(canvas, handlers) {
    this.canvas = canvas;
    this.context = canvas.getContext("2d", { alpha: false });
    this.handlers = handlers;
    this.newest = null; // {meta, jpeg} not yet decoded
    this.decoding = false;
    this.bitmap = null; // the frame shown, kept to redraw after a resize
    this.upscaler = new Upscaler();
  }

  /** A frame arrived: its `frame` message and the JPEG bytes (ArrayBuffer) that followed. */
  push(meta, jpeg) {
    this.newest = { meta, jpeg };
    if (!this.decoding) this.decodeNewest();
  }

  async decodeNewest() {
    this.decoding = true;
    while (this.newest) {
      const { meta, jpeg } = this.newest;
      this.newest = null;
      try {
        const bitmap = await decodeFrame(meta, jpeg); // one JPEG, or its bands drawn in place (bands.js)
        this.bitmap?.close();
        this.bitmap = bitmap;
        this.draw();
        this.handlers.shown(meta);
      } catch (error) {
        this.handlers.failed(`a frame could not be decoded: ${error.message}`);
      }
    }
    this.decoding = false;
  }

  /** Resize the canvas to the painting's full size (clears it), and draw the frame shown again. */
  resize(width, height) {
    [this.canvas.width, this.canvas.height] = [width, height];
    this.draw();
  }

  draw() {
    if (!this.bitmap) return;
    const { width, height } = this.canvas;
    if (this.upscaler.wanted(this.bitmap.width, this.bitmap.height, width, height)) {
      if (this.upscaler.draw(this.bitmap, this.context, width, height)) return;
    }
    this.context.imageSmoothingEnabled = true;
    this.context.imageSmoothingQuality = "high";
    this.context.drawImage(this.bitmap, 0, 0, this.canvas.width, this.canvas.height);
  }
}
