// @ts-check
// Playback: the walk follows the server's camera of every frame (POST /api/paths: the spline is declared once,
// in rcp_server/media/camerapath.py, so what plays here is what the video paints), at the path's frame rate,
// each frame painted with the painting the path keys there (as scrubbing shows it, scrub.js).

export class Player {
  /**
   * `toggle` is the Play button. `hooks`: cameras() -> the server's answer for the path ({cameras, paints,
   * fps}); place(camera) moves the walk; keyed(table) has it paint the path's keyed settings there (null:
   * none); loop() -> whether the path loops; notice(text).
   * @param {HTMLElement} toggle
   * @param {{cameras: () => Promise<{cameras: any[], paints: any[], fps: number}>, place: (camera: any) => void,
   *   keyed: (table: any) => void, loop: () => boolean, notice: (text: string) => void}} hooks
   */
  constructor(toggle, hooks) {
    this.toggle = toggle;
    this.hooks = hooks;
    /** @type {{cameras: any[], paints: any[], fps: number, start: number, frame: number} | null} */
    this.playing = null;
    this.step = this.step.bind(this);
  }

  /** Play, or stop playing. */
  async play() {
    if (this.playing) return this.stop();
    try {
      const answer = await this.hooks.cameras();
      const { cameras, paints, fps } = answer;
      this.playing = { cameras, paints, fps, start: performance.now(), frame: -1 };
      this.toggle.textContent = "Stop";
      requestAnimationFrame(this.step);
    } catch (error) {
      this.hooks.notice(`Cannot play the path: ${error.message}`);
    }
  }

  /** @param {number} now */
  step(now) {
    const playing = this.playing;
    if (!playing) return;
    let frame = Math.floor(((now - playing.start) / 1000) * playing.fps);
    if (frame >= playing.cameras.length) {
      if (!this.hooks.loop()) return this.stop();
      frame %= playing.cameras.length;
    }
    if (frame !== playing.frame) {
      playing.frame = frame;
      this.hooks.place(playing.cameras[frame]);
      this.hooks.keyed(playing.paints[frame] ?? null);
    }
    requestAnimationFrame(this.step);
  }

  stop() {
    this.playing = null;
    this.toggle.textContent = "Play";
  }
}
