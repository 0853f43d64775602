// @ts-check
// The film: the path rendered by the server into an MP4 (POST /api/videos), its progress bar following the
// job's `done_frames` (each value seen kept in `progress`, for the tests), cancelled, and its file downloaded.

const POLL_MS = 500;

export class Film {
  /**
   * `$(name)` finds the panel's parts (`job`, `progress`, `status`, `cancel`, `download`). `hooks`:
   * call(url, method, body) -> the answer; download(url) -> the file as a Blob; name() -> the file's name;
   * changed() after a job starts or ends; notice(text).
   * @param {(name: string) => any} $
   * @param {{call: (url: string, method: string, body?: any) => Promise<any>, download: (url: string) => Promise<Blob>,
   *   name: () => string, changed: () => void, notice: (text: string) => void}} hooks
   */
  constructor($, hooks) {
    this.$ = $;
    this.hooks = hooks;
    /** @type {{id: string, frames: number, timer?: number} | null} */
    this.job = null;
    this.progress = /** @type {number[]} */ ([]); // the progress bar's values during the last render
  }

  /** Ask for the film of `body` (a VideoRequest), then watch it. */
  async submit(body) {
    if (this.job) return;
    try {
      const created = await this.hooks.call("api/videos", "POST", body);
      this.job = { id: created.id, frames: created.frames };
      this.started(created.frames);
      this.job.timer = setInterval(() => this.poll(), POLL_MS);
    } catch (error) {
      this.hooks.notice(`Cannot render the path: ${error.message}`);
    }
  }

  /** @param {number} frames */
  started(frames) {
    const $ = this.$;
    $("progress").max = frames;
    $("progress").value = 0;
    this.progress.splice(0, this.progress.length, 0);
    $("job").hidden = false;
    $("download").hidden = true;
    $("cancel").hidden = false;
    $("status").textContent = `queued · ${frames} frames`;
    this.hooks.changed();
  }

  async poll() {
    const job = this.job;
    if (!job) return;
    let status;
    try {
      status = await this.hooks.call(`api/videos/${job.id}`, "GET");
    } catch (error) {
      return this.finish(`failed: ${error.message}`);
    }
    if (!this.job) return; // ended meanwhile (a cancel's poll)
    this.$("progress").value = status.done_frames;
    if (this.progress.at(-1) !== status.done_frames) this.progress.push(status.done_frames);
    this.$("status").textContent = `${status.state} · ${status.done_frames} / ${status.frames} frames`;
    if (status.state === "done") {
      const link = this.$("download");
      link.href = URL.createObjectURL(await this.hooks.download(`api/videos/${job.id}/file`));
      link.download = this.hooks.name();
      link.hidden = false;
      this.finish("done");
    } else if (status.state === "failed" || status.state === "cancelled") {
      this.finish(`${status.state}${status.message ? `: ${status.message}` : ""}`);
    }
  }

  /** @param {string} text */
  finish(text) {
    if (!this.job) return; // a cancel's poll and the timer's can both end a job: the first ends it
    clearInterval(this.job.timer);
    this.$("cancel").hidden = true;
    this.$("status").textContent = text;
    this.job = null;
    this.hooks.changed();
  }

  async cancel() {
    if (!this.job) return;
    try {
      await this.hooks.call(`api/videos/${this.job.id}`, "DELETE");
    } catch (error) {
      this.hooks.notice(`Cannot cancel: ${error.message}`);
    }
    this.poll();
  }
}
