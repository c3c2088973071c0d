// The door bar of the study page, shown with both views, driven by where the simulator has her
// (HumanState, forwarded by the server in the `study` state).
//
// Virtual doors: at her desk one "Go to <door>" button per door she operates; walking there,
// "Walking to the door…" and "Turn back"; at the door, a press-and-hold "Hold to open the door"
// that must be held for the door's opening time (HumanState.open_time site seconds, turned into
// wall seconds with the site clock's rate) while a ring fills — releasing early opens nothing; on
// the way back, "Walking back…". Real doors (door_control "sensor"): no buttons, only the doors'
// states. Each request waits for the simulator's answer (a new HumanState) before another.

import { el } from "./dom.js";

const ANSWER_WAIT_MS = 6000; // a door request unanswered this long: the buttons come back
const RING = 44; // px, the progress ring's canvas

export class DoorBar {
  constructor(root, { send, site }) {
    this.root = root;
    this.send = send; // (message) => bool
    this.site = site;
    this.study = null;
    this.world = null;
    this.key = "";
    this.hold = null; // {start, need, door, pointer}
    this.pending = null; // {act, door, at, place, doorWas}: a request sent, the simulator's answer not yet seen
    this.message = "";
    this.events = []; // what happened to holds and requests, for tests and the experimenter
    this.ring = null;
  }

  update(study, world) {
    this.study = study;
    this.world = world || this.world;
    const h = study && study.human;
    if (this.pending && (!h || h.place !== this.pending.place || h.door !== this.pending.doorWas || performance.now() - this.pending.at > ANSWER_WAIT_MS)) {
      this.pending = null; // the simulator answered (or never will)
    }
    if (this.hold && study.paused) this.cancelHold("paused by the experimenter");
    else if (this.hold && (!h || h.place !== "at_door")) this.cancelHold("the door is no longer in reach");
    const key = JSON.stringify([this.doorControl, h && [h.place, h.door, h.doors, h.open_time], study && study.paused,
      study && study.wall_rate, this.pending && this.pending.act, this.message, this.doorControl === "sensor" ? this.doorStates() : null]);
    if (key !== this.key && !this.hold) {
      this.key = key;
      this.render();
    }
  }

  onRefused(reason) {
    this.pending = null;
    this.events.push({ refused: reason });
    this.message = `Not done: ${reason}`;
    this.key = "";
    this.update(this.study, this.world);
  }

  get doorControl() {
    return this.study ? this.study.door_control : "virtual";
  }

  myDoors() {
    const h = this.study && this.study.human;
    if (h && h.doors.length) return h.doors;
    return Object.entries(this.site.doors).filter(([, d]) => d.human_operated).map(([did]) => did);
  }

  doorStates() {
    const doors = (this.world && this.world.doors) || {};
    return this.myDoors().map((did) => [did, did in doors ? (doors[did] ? "open" : "closed") : "unknown"]);
  }

  // Wall milliseconds the press-and-hold lasts: open_time site seconds at the clock's rate.
  needMs() {
    const h = this.study.human;
    const rate = this.study.wall_rate > 0 ? this.study.wall_rate : 1;
    return (1000 * (h ? h.open_time : 0)) / rate;
  }

  say(text) {
    this.message = text;
    const node = this.root.querySelector(".door-message");
    if (node) node.textContent = text;
  }

  // ------------------------------------------------------------------ drawing

  render() {
    const parts = [];
    const status = (text) => parts.push(el("span", { class: "door-status", id: "door-status", role: "status", text }));
    const h = this.study && this.study.human;
    this.ring = null;
    if (this.doorControl === "sensor") {
      status("Doors:");
      for (const [did, st] of this.doorStates()) parts.push(el("span", { class: `door-state ${st}`, "data-door": did, text: `${did} ${st}` }));
    } else if (!h) {
      status("Waiting for the simulator to say where you are…");
    } else if (this.pending) {
      status(this.pending.act === "go_to_door" ? `Leaving for ${this.pending.door}…` : this.pending.act === "open_door" ? `Opening ${this.pending.door}…` : "Turning back…");
    } else if (h.place === "desk") {
      status("At your desk.");
      for (const did of h.doors) {
        const b = el("button", { type: "button", class: "go", id: `go-${did}`, "data-door": did, text: `Go to ${did}` });
        b.addEventListener("click", () => this.request("go_to_door", did));
        parts.push(b);
      }
    } else if (h.place === "to_door") {
      status(`Walking to the door ${h.door}…`);
      parts.push(this.turnBack());
    } else if (h.place === "at_door") {
      status(`At the door ${h.door}.`);
      parts.push(this.holdButton(h.door), this.turnBack());
    } else {
      status("Walking back…");
    }
    parts.push(el("span", { class: "door-message", role: "status", text: this.message }));
    this.root.replaceChildren(...parts);
    this.root.hidden = false;
  }

  turnBack() {
    const b = el("button", { type: "button", class: "back", id: "turn-back", text: "Turn back" });
    b.addEventListener("click", () => this.request("back_to_desk", ""));
    return b;
  }

  holdButton(door) {
    const canvas = el("canvas", { class: "ring", width: RING, height: RING });
    const seconds = this.needMs() / 1000;
    const button = el("button", { type: "button", class: "hold", id: "hold-open", "data-door": door },
      canvas, el("span", { text: "Hold to open the door" }), el("small", { text: `${seconds.toFixed(1)} s` }));
    button.addEventListener("pointerdown", (e) => this.startHold(e, button, door));
    button.addEventListener("pointerup", () => this.endHold());
    button.addEventListener("pointercancel", () => this.cancelHold("the press was interrupted"));
    button.addEventListener("lostpointercapture", () => this.endHold());
    button.addEventListener("contextmenu", (e) => e.preventDefault()); // a long press must not open a menu
    this.ring = canvas;
    this.drawRing(0);
    return button;
  }

  drawRing(fraction) {
    if (!this.ring) return;
    const ctx = this.ring.getContext("2d");
    const c = RING / 2;
    ctx.clearRect(0, 0, RING, RING);
    ctx.lineWidth = 6;
    ctx.strokeStyle = "#555";
    ctx.beginPath();
    ctx.arc(c, c, c - 4, 0, 2 * Math.PI);
    ctx.stroke();
    if (fraction > 0) {
      ctx.strokeStyle = "#3cc850";
      ctx.beginPath();
      ctx.arc(c, c, c - 4, -Math.PI / 2, -Math.PI / 2 + 2 * Math.PI * Math.min(1, fraction));
      ctx.stroke();
    }
  }

  // ------------------------------------------------------------------ requests

  request(act, door) {
    if (this.pending) return;
    const h = this.study.human;
    this.say("");
    if (this.send({ type: "door", act, door })) {
      // The answer is a new place or door: remember what they were when asked.
      this.pending = { act, door: door || (h ? h.door : ""), at: performance.now(), place: h ? h.place : "", doorWas: h ? h.door : "" };
      this.events.push({ sent: act, door });
      setTimeout(() => this.update(this.study, this.world), ANSWER_WAIT_MS + 50);
    } else {
      this.say("Not connected: nothing was sent.");
    }
    this.key = "";
    this.update(this.study, this.world);
  }

  startHold(e, button, door) {
    if (this.hold || this.pending || this.study.paused) return;
    e.preventDefault();
    try {
      button.setPointerCapture(e.pointerId);
    } catch (_) {
      // a synthetic pointer cannot be captured: the hold still ends on its pointerup
    }
    this.say("");
    this.hold = { start: performance.now(), need: this.needMs(), door };
    const tick = () => {
      if (!this.hold) return;
      const fraction = this.hold.need > 0 ? (performance.now() - this.hold.start) / this.hold.need : 1;
      this.drawRing(fraction);
      if (fraction >= 1) this.completeHold();
      else requestAnimationFrame(tick);
    };
    tick();
  }

  endHold() {
    if (!this.hold) return;
    const held = (performance.now() - this.hold.start) / 1000;
    this.cancelHold(`released after ${held.toFixed(1)} s: hold until the ring is full (${(this.hold.need / 1000).toFixed(1)} s)`, held);
  }

  cancelHold(why, held = null) {
    if (!this.hold) return;
    this.hold = null;
    this.drawRing(0);
    this.events.push({ released: held, why });
    this.say(why.charAt(0).toUpperCase() + why.slice(1) + ".");
    this.key = "";
  }

  completeHold() {
    const held = (performance.now() - this.hold.start) / 1000;
    const door = this.hold.door;
    this.hold = null;
    this.events.push({ held });
    const h = this.study.human;
    if (this.send({ type: "door", act: "open_door", door, held: Math.round(held * 1000) / 1000 })) {
      this.pending = { act: "open_door", door, at: performance.now(), place: h.place, doorWas: h.door };
      this.events.push({ sent: "open_door", door });
      setTimeout(() => this.update(this.study, this.world), ANSWER_WAIT_MS + 50);
    } else {
      this.say("Not connected: the door was not opened.");
    }
    this.key = "";
    this.update(this.study, this.world);
  }

  snapshot() {
    const status = this.root.querySelector(".door-status");
    return {
      status: status ? status.textContent : "",
      buttons: Array.from(this.root.querySelectorAll("button")).map((b) => b.id),
      holding: this.hold !== null,
      progress: this.hold ? Math.min(1, (performance.now() - this.hold.start) / this.hold.need) : 0,
      need_s: this.study && this.study.human ? this.needMs() / 1000 : null,
      pending: this.pending ? this.pending.act : null,
      message: this.message,
      events: this.events.slice(),
    };
  }
}
