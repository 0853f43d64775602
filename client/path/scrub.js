// @ts-check
// Scrubbing: the walk shows the path at a chosen time, the server's camera of the frame there (the path's
// cameras asked once for each path, POST /api/paths).

export class Scrubber {
  /**
   * `hooks`: spec() -> the path as the CLI takes it; scene() -> the SceneInfo shown or null; call(url, method,
   * body) -> the answer; stop() ends a playback; place(camera) moves the walk; notice(text).
   * @param {{spec: () => any, scene: () => any, call: (url: string, method: string, body?: any) => Promise<any>,
   *   stop: () => void, place: (camera: any) => void, notice: (text: string) => void}} hooks
   */
  constructor(hooks) {
    this.hooks = hooks;
    /** @type {{t: number, frame: number} | null} the last time scrubbed to, and the frame shown */
    this.scrubbed = null;
    /** @type {{spec: string, answer: any} | null} the server's cameras of the path as it was last scrubbed */
    this.preview = null;
  }

  /** The walk shows the path at `t` seconds. @param {number} t */
  async scrub(t) {
    const scene = this.hooks.scene();
    const spec = this.hooks.spec();
    if (!scene || spec.keyframes.length < 2) return;
    this.hooks.stop();
    const asked = JSON.stringify(spec);
    try {
      if (this.preview?.spec !== asked) {
        const answer = await this.hooks.call("api/paths", "POST", { scene: scene.name, path: spec });
        this.preview = { spec: asked, answer };
      }
      const { cameras, fps } = this.preview.answer;
      const frame = Math.min(cameras.length - 1, Math.round(t * fps));
      this.scrubbed = { t, frame };
      this.hooks.place(cameras[frame]);
    } catch (error) {
      this.hooks.notice(`Cannot show the path at ${t} s: ${error.message}`);
    }
  }
}
