// The participant's Jigsaw puzzle: the board of pieces, the picture to make, progress.
//
// The server owns the puzzle (services/ar_client/web/puzzle.py): this board draws the arrangement
// it sends (`slots[s]` = the piece lying in slot s; piece p belongs in slot p) and asks it for
// moves. A tap on a piece picks it up, a tap on another swaps the two (dragging one onto another
// does the same); a piece in its own place is locked. Until the server answers a move the board
// waits, so the page never shows an arrangement the server does not have.
//
// The picture is the server's /puzzle.png (drawn from the trial's seed); each piece is a canvas
// showing its part of it.

import { el } from "./dom.js";

const ANSWER_WAIT_MS = 4000; // a move unanswered this long: the board takes taps again

export class PuzzleBoard {
  constructor({ board, reference, progress, message, lock }, { send }) {
    this.boardEl = board;
    this.referenceEl = reference;
    this.progressEl = progress;
    this.messageEl = message;
    this.lockEl = lock;
    this.send = send; // (message) => bool
    this.state = null; // the server's puzzle state
    this.lockReason = "";
    this.selected = null; // slot of the piece picked up
    this.pending = null; // {moves, at}: a move sent, waiting for the server
    this.down = null; // slot where a pointer went down
    this.tiles = [];
    this.image = null;
    this.imageReady = false;
    this.lastMessage = "";
    const image = new Image();
    image.addEventListener("load", () => {
      this.imageReady = true;
      this.draw();
    });
    image.addEventListener("error", () => this.say("The puzzle's picture did not load; reload the page."));
    image.src = "/puzzle.png";
    this.image = image;
    board.addEventListener("pointerdown", (e) => this.onDown(e));
    board.addEventListener("pointerup", (e) => this.onUp(e));
    board.addEventListener("pointercancel", () => (this.down = null));
    board.addEventListener("contextmenu", (e) => e.preventDefault());
  }

  // The server's puzzle state and why it is locked now ("" = playable).
  setState(state, lockReason) {
    const fresh = !this.state || this.state.rows !== state.rows || this.state.cols !== state.cols;
    const moved = this.state && this.state.moves !== state.moves;
    this.state = state;
    this.lockReason = lockReason || "";
    if (fresh) this.build();
    if (this.pending && (moved || state.moves !== this.pending.moves)) this.pending = null;
    if (this.selected !== null && (this.isLocked(this.selected) || this.lockReason)) this.selected = null;
    this.draw();
  }

  // The server turned a move down: show why, and take taps again.
  onRefused(reason) {
    this.pending = null;
    this.selected = null;
    this.say(`Not moved: ${reason}`);
    this.draw();
  }

  build() {
    const { rows, cols } = this.state;
    this.boardEl.style.setProperty("--rows", rows);
    this.boardEl.style.setProperty("--cols", cols);
    this.tiles = [];
    const buttons = [];
    for (let s = 0; s < rows * cols; s++) {
      const canvas = el("canvas", { class: "piece" });
      const tile = el("button", { type: "button", class: "tile", "data-slot": s, "aria-label": `row ${Math.floor(s / cols) + 1}, column ${(s % cols) + 1}` }, canvas);
      this.tiles.push({ tile, canvas, piece: -1 });
      buttons.push(tile);
    }
    this.boardEl.replaceChildren(...buttons);
  }

  isLocked(slot) {
    return this.state && this.state.slots[slot] === slot;
  }

  get busy() {
    if (this.pending && performance.now() - this.pending.at > ANSWER_WAIT_MS) this.pending = null;
    return this.pending !== null;
  }

  // ------------------------------------------------------------------ input

  slotAt(x, y) {
    const hit = document.elementFromPoint(x, y);
    const tile = hit && hit.closest ? hit.closest(".tile") : null;
    return tile && this.boardEl.contains(tile) ? Number(tile.dataset.slot) : null;
  }

  onDown(e) {
    const tile = e.target.closest(".tile");
    this.down = tile ? Number(tile.dataset.slot) : null;
  }

  onUp(e) {
    const from = this.down;
    this.down = null;
    if (from === null) return;
    const to = this.slotAt(e.clientX, e.clientY);
    if (to === null) return;
    if (to !== from) this.swap(from, to); // dragged one piece onto another
    else this.tap(to);
  }

  tap(slot) {
    if (!this.playable()) return;
    if (this.isLocked(slot)) {
      this.say("That piece is in its place.");
      return;
    }
    if (this.selected === null) this.selected = slot;
    else if (this.selected === slot) this.selected = null;
    else return this.swap(this.selected, slot);
    this.say("");
    this.draw();
  }

  swap(a, b) {
    if (!this.playable() || this.isLocked(a) || this.isLocked(b)) return;
    const piece = this.state.slots[a];
    const other = this.state.slots[b];
    this.selected = null;
    if (this.send({ type: "puzzle_move", piece, other })) {
      this.pending = { moves: this.state.moves, at: performance.now() };
      this.say("");
    } else {
      this.say("Not connected: the move was not made.");
    }
    this.draw();
  }

  playable() {
    return this.state && !this.state.done && !this.lockReason && !this.busy;
  }

  // ------------------------------------------------------------------ drawing

  say(text) {
    this.lastMessage = text;
    this.messageEl.textContent = text;
  }

  draw() {
    const s = this.state;
    if (!s) return;
    const { rows, cols } = s;
    const image = this.image;
    const pw = this.imageReady ? image.naturalWidth / cols : 0;
    const ph = this.imageReady ? image.naturalHeight / rows : 0;
    for (let slot = 0; slot < this.tiles.length; slot++) {
      const t = this.tiles[slot];
      const piece = s.slots[slot];
      const locked = piece === slot;
      t.tile.classList.toggle("locked", locked);
      t.tile.classList.toggle("selected", this.selected === slot);
      // aria-disabled, not disabled: a disabled button would swallow the pointer events of a tap.
      t.tile.setAttribute("aria-disabled", String(locked || s.done || Boolean(this.lockReason)));
      if (this.imageReady && t.piece !== piece) {
        t.canvas.width = Math.round(pw);
        t.canvas.height = Math.round(ph);
        const ctx = t.canvas.getContext("2d");
        ctx.drawImage(image, (piece % cols) * pw, Math.floor(piece / cols) * ph, pw, ph, 0, 0, t.canvas.width, t.canvas.height);
        t.piece = piece;
      }
    }
    this.boardEl.classList.toggle("waiting", this.pending !== null);
    this.boardEl.classList.toggle("done", s.done);
    if (this.imageReady && !this.referenceDrawn) {
      const ref = this.referenceEl;
      ref.width = image.naturalWidth;
      ref.height = image.naturalHeight;
      ref.getContext("2d").drawImage(image, 0, 0);
      this.referenceDrawn = true;
    }
    this.progressEl.textContent = s.done
      ? `Puzzle complete: all ${s.total} pieces in place in ${s.moves} moves. Well done!`
      : `${s.placed} of ${s.total} pieces in place · ${s.moves} move${s.moves === 1 ? "" : "s"}`;
    this.lockEl.hidden = !this.lockReason;
    this.lockEl.textContent = this.lockReason;
  }

  // What tests read: the arrangement as shown, the selection, whether a move waits.
  snapshot() {
    return {
      rows: this.state ? this.state.rows : 0,
      cols: this.state ? this.state.cols : 0,
      slots: this.state ? this.state.slots.slice() : [],
      shown: this.tiles.map((t) => t.piece),
      placed: this.state ? this.state.placed : 0,
      total: this.state ? this.state.total : 0,
      moves: this.state ? this.state.moves : 0,
      done: this.state ? this.state.done : false,
      selected: this.selected,
      pending: this.pending !== null,
      locked: this.lockReason,
      picture: this.imageReady,
      message: this.lastMessage,
    };
  }
}
