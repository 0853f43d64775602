// @ts-check
// Undo and redo for the camera path: every change is taken as a whole snapshot of the keyframes (a path is
// small: a few hundred keyframes at most), so an undo is exact whatever the change was.

const DEPTH = 200; // changes kept to undo

export class History {
  /** `read()` -> the state to keep (plain JSON data); `write(state)` puts one back. */
  constructor(read, write) {
    this.read = read;
    this.write = write;
    this.done = [];
    this.undone = [];
  }

  /** Call before a change: what is there now becomes the step an undo returns to. */
  record() {
    this.push(JSON.stringify(this.read()));
  }

  /** A state taken before a change (as JSON text), kept once the change proved to change something. */
  push(before) {
    if (this.done.at(-1) === before && before === JSON.stringify(this.read())) return; // nothing changed
    this.done.push(before);
    if (this.done.length > DEPTH) this.done.shift();
    this.undone = [];
  }

  undo() {
    if (!this.done.length) return false;
    this.undone.push(JSON.stringify(this.read()));
    this.write(JSON.parse(this.done.pop()));
    return true;
  }

  redo() {
    if (!this.undone.length) return false;
    this.done.push(JSON.stringify(this.read()));
    this.write(JSON.parse(this.undone.pop()));
    return true;
  }
}
