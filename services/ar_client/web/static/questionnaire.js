// The questionnaire after a trial, built from the instruments the server sends (their wording and
// scales live in services/ar_client/web/questionnaire.py): the paper's Q1–Q5 on 1–5 with its labels,
// and raw NASA-TLX (0–100 in steps of 5, the form's end anchors) when the trial lists it.
// Every item must be answered before Submit; the server checks the answers again.

import { el } from "./dom.js";

export class Questionnaire {
  constructor(root, { send }) {
    this.root = root;
    this.send = send; // (message) => bool
    this.instruments = [];
    this.answers = {}; // instrument -> item -> value
    this.pending = false;
    this.submitButton = null;
    this.left = null;
    this.result = null;
  }

  build(instruments) {
    this.instruments = instruments || [];
    this.answers = Object.fromEntries(this.instruments.map((i) => [i.id, {}]));
    const sections = this.instruments.map((inst) => this.section(inst));
    this.submitButton = el("button", { type: "button", id: "q-submit", class: "submit", text: "Submit" });
    this.submitButton.addEventListener("click", () => this.submit());
    this.left = el("div", { class: "q-left", id: "q-left", role: "status" });
    this.result = el("div", { class: "q-result", id: "q-result", role: "status" });
    this.root.replaceChildren(
      el("h1", { text: "Questionnaire" }),
      ...sections,
      el("div", { class: "q-footer" }, this.left, this.submitButton, this.result),
    );
    this.refresh();
  }

  section(inst) {
    const items = inst.items.map((item, n) => {
      const name = `${inst.id}:${item.id}`;
      const likert = Object.keys(inst.labels).length > 0;
      const options = inst.values.map((v) => {
        const input = el("input", { type: "radio", name, value: v, id: `q-${inst.id}-${item.id}-${v}` });
        input.addEventListener("change", () => {
          this.answers[inst.id][item.id] = v;
          this.refresh();
        });
        const text = likert ? [el("span", { class: "v", text: String(v) }), el("small", { text: inst.labels[String(v)] })]
          : [el("span", { class: "v", text: String(v) })];
        return el("label", { class: "opt", for: input.id, "data-item": name, "data-value": v }, input, ...text);
      });
      const heading = likert ? `Q${n + 1}. ${item.text}` : `${item.title}: ${item.text}`;
      const scale = el("div", { class: likert ? "scale likert" : "scale tlx", role: "radiogroup", "aria-label": heading }, ...options);
      const ends = likert ? null : el("div", { class: "anchors" }, el("span", { text: item.low }), el("span", { text: item.high }));
      return el("div", { class: "q-item", "data-item": name }, el("div", { class: "q-text", text: heading }), scale, ends);
    });
    return el("section", { class: "instrument", "data-instrument": inst.id },
      el("h2", { text: inst.title }), el("p", { class: "intro", text: inst.intro }), ...items);
  }

  missing() {
    const out = [];
    for (const inst of this.instruments) for (const item of inst.items) if (!(item.id in this.answers[inst.id])) out.push(`${inst.id}:${item.id}`);
    return out;
  }

  refresh() {
    const missing = this.missing();
    for (const node of this.root.querySelectorAll(".q-item")) node.classList.toggle("answered", !missing.includes(node.dataset.item));
    if (this.submitButton) this.submitButton.disabled = missing.length > 0 || this.pending;
    if (this.left) this.left.textContent = missing.length ? `${missing.length} item${missing.length === 1 ? "" : "s"} left to answer` : "All answered.";
  }

  submit() {
    if (this.pending || this.missing().length) return;
    if (this.send({ type: "answers", answers: this.answers })) {
      this.pending = true;
      this.result.textContent = "Sending…";
    } else {
      this.result.textContent = "Not connected: try again in a moment.";
    }
    this.refresh();
  }

  onRefused(reason) {
    this.pending = false;
    this.result.textContent = `Not accepted: ${reason}`;
    this.refresh();
  }

  snapshot() {
    return { missing: this.missing(), pending: this.pending, result: this.result ? this.result.textContent : "", answers: this.answers };
  }
}
