// @ts-check
// Scrubbing: the walk shows the path at a chosen time, the server's camera of the frame there, painted with the
// painting the path keys there (its `paint` keyframes: POST /api/paths names it for each frame over the film's
// painting, by the rule the film paints with, so nothing of it is computed here). The path's frames are asked
// once for each path and film painting.

export class Scrubber {
  /**
   * `hooks`: spec() -> the path as the CLI takes it; paint() -> the film's painting (a render's `paint`);
   * scene() -> the SceneInfo shown or null; call(url, method, body) -> the answer; stop() ends a playback;
   * place(camera) moves the walk; keyed(table) has it paint the path's keyed settings there (null: none);
   * notice(text).
   * @param {{spec: () => any, paint: () => any, scene: () => any,
   *   call: (url: string, method: string, body?: any) => Promise<any>, stop: () => void,
   *   place: (camera: any) => void, keyed: (table: any) => void, notice: (text: string) => void}} hooks
   */
  constructor(hooks) {
    this.hooks = hooks;
    /** @type {{t: number, frame: number} | null} the last time scrubbed to, and the frame shown */
    this.scrubbed = null;
    /** @type {{spec: string, answer: any} | null} the server's frames of the path as it was last scrubbed */
    this.preview = null;
  }

  /** The walk shows the path at `t` seconds. @param {number} t */
  async scrub(t) {
    const scene = this.hooks.scene();
    const spec = this.hooks.spec();
    if (!scene || spec.keyframes.length < 2) return;
    this.hooks.stop();
    const body = { scene: scene.name, path: spec, paint: this.hooks.paint() };
    const asked = JSON.stringify(body);
    try {
      if (this.preview?.spec !== asked) {
        this.preview = { spec: asked, answer: await this.hooks.call("api/paths", "POST", body) };
      }
      const { cameras, paints, fps } = this.preview.answer;
      const frame = Math.min(cameras.length - 1, Math.round(t * fps));
      this.scrubbed = { t, frame };
      this.hooks.place(cameras[frame]);
      this.hooks.keyed(paints[frame] ?? null);
    } catch (error) {
      this.hooks.notice(`Cannot show the path at ${t} s: ${error.message}`);
    }
  }
}
