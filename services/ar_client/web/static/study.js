// The study page (arroch tablet --study-trial FILE): the page a participant uses during a trial.
//
// The trial file decides the condition, so the page shows no Viewer/Map toggles; a tab bar switches
// between her own task ("Puzzle") and the robots ("Robots": the sim's camera with the AR overlay,
// plus the feedback panel in the ARROCH condition; the map alone in the map condition). The door
// bar (doorbar.js) is shown with both. Screens over everything, in this order: consent (when the
// trial asks for it) → declined ("the experimenter will take over") → thank you → questionnaire
// (once the mission ended, or ?questionnaire=1 for the experimenter) → paused.
//
// Everything she does is a request to the server, which judges it and records it on Zenoh. Each
// request carries `wall` (Date.now()/1000 when she acted). Which view she sees is reported on
// every switch and when the page is hidden or shown again (visibilitychange), so time away from
// the puzzle is measured.

import { $, el, plainTextBlocks } from "./dom.js";
import { DoorBar } from "./doorbar.js";
import { PuzzleBoard } from "./puzzle.js";
import { Questionnaire } from "./questionnaire.js";

export class StudyPage {
  constructor({ send, early }) {
    this.sendRaw = send; // (message object) => bool
    this.early = early; // the experimenter opened the questionnaire early (?questionnaire=1)
    this.state = null;
    this.world = null;
    this.tab = "puzzle";
    this.announced = false; // the current view was reported on this connection
    this.sent = []; // every request, with whether it left (for tests)
    this.refusals = [];
    this.puzzle = null;
    this.doors = null;
    this.questionnaire = null;
  }

  // The hello of a connection: (re)build what depends on the trial, then draw its state.
  start(hello) {
    const study = hello.study;
    document.body.classList.add("study");
    document.body.classList.toggle("with-feedback", study.feedback);
    document.body.dataset.condition = study.condition;
    if (!this.puzzle) {
      this.puzzle = new PuzzleBoard(
        { board: $("puzzle-board"), reference: $("puzzle-ref"), progress: $("puzzle-progress"), message: $("puzzle-message"), lock: $("puzzle-lock") },
        { send: (m) => this.request(m) },
      );
      this.doors = new DoorBar($("doorbar"), { send: (m) => this.request(m), site: hello.site });
      this.questionnaire = new Questionnaire($("questionnaire"), { send: (m) => this.request(m) });
      this.questionnaire.build(study.instruments);
      this.buildConsent(study.consent.text);
      $("tab-puzzle").addEventListener("click", () => this.setTab("puzzle"));
      $("tab-robots").addEventListener("click", () => this.setTab("robots"));
      document.addEventListener("visibilitychange", () => this.report(document.hidden ? "hidden" : "visible"));
      $("tabs").hidden = false;
    }
    this.announced = false; // a new connection: tell the server what this page shows
    this.setTab(this.tab, { quiet: true });
    this.onState(study);
    this.onWorld(hello.world);
  }

  onState(state) {
    this.state = state;
    this.puzzle.setState(state.puzzle, state.puzzle_lock);
    this.doors.update(state, this.world);
    this.render();
  }

  onWorld(world) {
    this.world = world;
    if (this.state) this.doors.update(this.state, world);
  }

  onRefused(msg) {
    this.refusals.push(msg);
    if (msg.what === "puzzle_move") this.puzzle.onRefused(msg.reason);
    else if (msg.what === "door") this.doors.onRefused(msg.reason);
    else if (msg.what === "answers") this.questionnaire.onRefused(msg.reason);
    else if (msg.what === "consent") $("consent-result").textContent = `Not recorded: ${msg.reason}`;
  }

  request(message) {
    message.wall = Date.now() / 1000;
    const ok = this.sendRaw(message);
    this.sent.push({ ...message, ok });
    if (this.sent.length > 2000) this.sent.splice(0, 1000);
    return ok;
  }

  // ------------------------------------------------------------------ screens

  screen() {
    const s = this.state;
    if (!s) return "";
    if (s.consent.required && s.consent.answer === "refused") return "declined";
    if (s.consent.required && !s.consent.answer) return "consent";
    if (s.submitted) return "thanks";
    if (s.mission_done || this.early) return "questionnaire";
    if (s.paused) return "paused";
    return "";
  }

  render() {
    const screen = this.screen();
    document.body.dataset.screen = screen;
    for (const id of ["consent", "declined", "thanks", "questionnaire", "paused"]) $(id).hidden = id !== screen;
    // The main page is in use (not behind a full screen): its view is what she sees.
    if (this.inUse() && !this.announced) this.report("");
  }

  inUse() {
    const screen = this.screen();
    return screen === "" || screen === "paused";
  }

  buildConsent(text) {
    const agree = el("button", { type: "button", id: "consent-agree", class: "agree", text: "I agree" });
    const refuse = el("button", { type: "button", id: "consent-refuse", class: "refuse", text: "I do not agree" });
    agree.addEventListener("click", () => this.answerConsent("given"));
    refuse.addEventListener("click", () => this.answerConsent("refused"));
    const blocks = plainTextBlocks(text);
    // The form's own heading, if it has one; else a plain title.
    const titled = blocks.length && blocks[0].tagName === "H2";
    $("consent").replaceChildren(
      ...(titled ? [] : [el("h1", { text: "Consent" })]),
      el("div", { class: "consent-text", id: "consent-text" }, ...blocks),
      el("div", { class: "consent-buttons" }, agree, refuse),
      el("div", { class: "q-result", id: "consent-result", role: "status" }),
    );
  }

  answerConsent(answer) {
    if (!this.request({ type: "consent", answer })) $("consent-result").textContent = "Not connected: try again in a moment.";
  }

  // ------------------------------------------------------------------ views

  viewName(tab = this.tab) {
    return tab === "puzzle" ? "puzzle" : this.state ? this.state.robots_view : "ar";
  }

  setTab(tab, { quiet = false } = {}) {
    const changed = tab !== this.tab;
    this.tab = tab;
    document.body.dataset.tab = tab;
    $("tab-puzzle").classList.toggle("active", tab === "puzzle");
    $("tab-robots").classList.toggle("active", tab === "robots");
    $("tab-puzzle").setAttribute("aria-selected", String(tab === "puzzle"));
    $("tab-robots").setAttribute("aria-selected", String(tab === "robots"));
    window.dispatchEvent(new Event("resize")); // the stage and the map take their new size
    if (!quiet && (changed || !this.announced)) this.report("");
  }

  // Tell the server which view the page shows (note: "" a switch, "hidden"/"visible" the page itself).
  report(note) {
    if (!this.state || !this.inUse()) return;
    if (this.request({ type: "view", view: this.viewName(), note })) this.announced = true;
  }

  snapshot() {
    return {
      screen: this.screen(),
      tab: this.tab,
      view: this.viewName(),
      condition: this.state ? this.state.condition : null,
      consent: this.state ? this.state.consent.answer : null,
      human: this.state ? this.state.human : null,
      paused: this.state ? this.state.paused : false,
      mission_done: this.state ? this.state.mission_done : false,
      submitted: this.state ? this.state.submitted : false,
      task_done: this.state ? this.state.task_done : false,
      puzzle: this.puzzle ? this.puzzle.snapshot() : null,
      doors: this.doors ? this.doors.snapshot() : null,
      questionnaire: this.questionnaire ? this.questionnaire.snapshot() : null,
      sent: this.sent.map((m) => ({ ...m })),
      refusals: this.refusals.slice(),
    };
  }
}
