// Feedback buttons built from the constraint library the running restrictor serves (null until one
// answers: the panel then says it waits, and the server sends the library when it comes):
// one card per entry with a picker per parameter — minutes for "int" parameters, the site's doors,
// rooms or openings, the live constraints for a cancel — and a Send button. The answer (accepted
// with what the restrictor did, refused with its reason, or no answer) stays on the card.

const MINUTE_PRESETS = [1, 2, 5, 10, 15, 20, 30, 45, 60, 90, 120, 180, 240, 480];
const DEFAULT_MINUTES = 15;

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k === "text") node.textContent = v;
    else node.setAttribute(k, v);
  }
  for (const c of children) if (c) node.append(c);
  return node;
}

function describe(c) {
  const params = Object.entries(c.params).map(([k, v]) => `${k}=${v}`).join(", ");
  return `${c.id}: ${c.kind}(${params})`;
}

export class FeedbackPanel {
  constructor(root, send) {
    this.root = root;
    this.send = send; // (kind, params) => request id, or null when not connected
    this.cards = new Map(); // entry id -> {entry, inputs: Map(name -> select), button, result}
    this.pendingId = null;
    this.pendingEntry = null;
    this.constraints = [];
    this.now = null;
    this.results = []; // every answer, newest last (for tests and the record)
  }

  setLibrary(library) {
    this.root.replaceChildren();
    this.cards.clear();
    this.library = library;
    if (!library) {
      this.root.append(el("div", { class: "help", id: "library-waiting", role: "status",
        text: "Waiting for the restrictor: the feedback buttons appear as soon as it answers." }));
    }
    for (const entry of library || []) {
      const card = el("div", { class: "card", id: `entry-${entry.id}` });
      card.append(el("div", { class: "label", text: entry.label }));
      if (entry.help) card.append(el("div", { class: "help", text: entry.help }));
      const inputs = new Map();
      for (const p of entry.params) {
        const select = el("select", { id: `param-${entry.id}-${p.name}`, "aria-label": p.label, title: p.help || p.label });
        inputs.set(p.name, select);
        card.append(el("label", { class: "param" }, el("span", { text: p.label }), select));
      }
      const button = el("button", { type: "button", id: `send-${entry.id}`, class: "send", text: "Send" });
      const result = el("div", { class: "result", id: `result-${entry.id}`, role: "status" });
      card.append(button, result);
      button.addEventListener("click", () => this.press(entry.id));
      if (entry.usable === false) {
        button.disabled = true;
        result.textContent = "not available on this site";
      }
      this.cards.set(entry.id, { entry, inputs, button, result });
      this.root.append(card);
    }
    this.active = el("div", { class: "active", id: "active-constraints" });
    this.root.append(this.active);
    this.refreshChoices();
  }

  choices(p) {
    if (p.type === "int") {
      const lo = p.min ?? 1, hi = p.max ?? 240;
      const values = MINUTE_PRESETS.filter((v) => v >= lo && v <= hi);
      if (!values.includes(lo)) values.unshift(lo);
      if (!values.includes(hi)) values.push(hi);
      return values.map((v) => [String(v), p.name === "minutes" || /minute/i.test(p.label) ? `${v} min` : String(v)]);
    }
    if (p.type === "constraint" || p.source === "constraints") {
      return this.constraints.map((c) => [c.id, describe(c)]);
    }
    return (p.choices || []).map((v) => [v, v]);
  }

  refreshChoices() {
    for (const { entry, inputs, button } of this.cards.values()) {
      let ready = entry.usable !== false;
      for (const p of entry.params) {
        const select = inputs.get(p.name);
        const keep = select.value;
        const options = this.choices(p);
        select.replaceChildren(...options.map(([value, text]) => el("option", { value, text })));
        if (options.some(([v]) => v === keep)) select.value = keep;
        else if (p.type === "int") select.value = String(options.reduce((best, [v]) => (Math.abs(v - DEFAULT_MINUTES) < Math.abs(best - DEFAULT_MINUTES) ? Number(v) : best), Number(options[0][0])));
        if (!options.length) ready = false;
      }
      button.disabled = !ready || this.pendingId !== null;
    }
    if (this.active) {
      this.active.replaceChildren(el("div", { class: "label", text: this.constraints.length ? "Active constraints" : "No active constraints" }),
        ...this.constraints.map((c) => el("div", { class: "constraint", text: `${describe(c)}${this.until(c)}` })));
    }
  }

  until(c) {
    if (this.now === null || !(c.end > this.now)) return "";
    return ` — ${Math.ceil((c.end - this.now) / 60)} min left`;
  }

  setConstraints(items) {
    this.constraints = items || [];
    this.refreshChoices();
  }

  setNow(now) {
    this.now = now;
  }

  values(entryId) {
    const { entry, inputs } = this.cards.get(entryId);
    const params = {};
    for (const p of entry.params) {
      const raw = inputs.get(p.name).value;
      params[p.name] = p.type === "int" ? Number.parseInt(raw, 10) : raw;
    }
    return params;
  }

  press(entryId) {
    if (this.pendingId !== null) return;
    const card = this.cards.get(entryId);
    const params = this.values(entryId);
    const id = this.send(entryId, params);
    if (id === null) {
      this.show(card, "error", "not connected to the server");
      return;
    }
    this.pendingId = id;
    this.pendingEntry = entryId;
    this.show(card, "pending", "sending…");
    this.refreshChoices();
  }

  // The server's answer to a feedback request.
  onAck(msg) {
    const card = this.cards.get(msg.kind);
    if (msg.id === this.pendingId) {
      this.pendingId = null;
      this.pendingEntry = null;
    }
    this.results.push(msg);
    if (card) this.show(card, msg.status, msg.reason || "");
    this.refreshChoices();
  }

  // The link dropped: a request in flight will get no answer on this socket.
  onDisconnect() {
    if (this.pendingEntry !== null) this.show(this.cards.get(this.pendingEntry), "no answer", "connection lost before the answer");
    this.pendingId = null;
    this.pendingEntry = null;
    this.refreshChoices();
  }

  show(card, status, reason) {
    card.result.className = `result ${status.replace(" ", "-")}`;
    card.result.textContent = reason ? `${status}: ${reason}` : status;
  }
}
