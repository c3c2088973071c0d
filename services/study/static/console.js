// The experimenter's console: polls the trial's state once a second and sends the controls.
// Everything shown is set as text (never as HTML): what the participant's page sends cannot inject markup.
"use strict";

const POLL_MS = 1000;
let state = null;

const $ = (id) => document.getElementById(id);

function text(id, value) {
  $(id).textContent = value === null || value === undefined || value === "" ? "—" : String(value);
}

function rows(tbody, records) {
  const body = $(tbody);
  body.replaceChildren();
  for (const cells of records) {
    const tr = document.createElement("tr");
    for (const cell of cells) {
      const td = document.createElement("td");
      td.textContent = cell === null || cell === undefined || cell === "" ? "—" : String(cell);
      tr.appendChild(td);
    }
    body.appendChild(tr);
  }
}

function badge(id, label, kind) {
  const el = $(id);
  el.textContent = label;
  el.className = "badge" + (kind ? " " + kind : "");
}

function seconds(s) {
  if (s === null || s === undefined) return "—";
  const m = Math.floor(s / 60);
  return `${m}:${String(Math.floor(s % 60)).padStart(2, "0")} (${s.toFixed(1)} s)`;
}

function render(s) {
  state = s;
  text("participant", s.participant);
  text("trial", s.trial);
  badge("condition", s.condition, "");
  const phaseKind = s.phase === "complete" ? "ok" : s.phase === "incomplete" ? "bad" : s.phase === "consent" ? "warn" : "";
  badge("phase", s.phase, phaseKind);
  $("paused").hidden = !s.paused;
  badge("link", s.tablet_alive ? "tablet server up" : "tablet server down", s.tablet_alive ? "ok" : "warn");
  text("attempt", s.attempt);
  text("world", `${s.world} · ${s.world_state}`);
  text("site-time", seconds(s.site_time));
  text("wall", seconds(s.wall_elapsed));
  text("consent", s.consent);
  text("outcome", s.outcome || (s.mission_done ? "mission done" : ""));
  text("page", s.page);
  text("dropped", s.dropped);
  const urls = $("urls");
  urls.replaceChildren();
  for (const url of s.tablet_urls) {
    const li = document.createElement("li");
    li.textContent = url;
    urls.appendChild(li);
  }
  const h = s.human || {};
  text("place", h.place ? `${h.place}${h.door ? " (" + h.door + ")" : ""}${h.task_done ? " · task done" : ""}` : "");
  text("view", s.view);
  const p = s.puzzle;
  $("puzzle-bar").max = Math.max(p.total, 1);
  $("puzzle-bar").value = p.placed;
  text("puzzle", `${p.placed}/${p.total} placed, ${p.moves} moves${p.done ? " · done" : ""}`);
  const fb = s.feedback;
  text("feedback", fb.sent + (fb.last ? ` (last: ${fb.last.kind} ${fb.last.door} ${fb.last.minutes} min)` : ""));
  text("marks", s.marks);
  text(
    "questionnaires",
    Object.entries(s.questionnaires).map(([name, got]) => `${name}: ${got ? "received" : "waiting"}`).join(", "),
  );
  rows(
    "robots",
    Object.entries(s.robots).map(([id, r]) => [id, r.state, r.delivered, r.carrying, r.waiting_door]),
  );
  rows(
    "doors",
    Object.entries(s.doors).map(([id, d]) => [id, d.open ? "open" : "closed", d.by]),
  );
  const recent = $("recent");
  recent.replaceChildren();
  for (const item of s.recent) {
    const li = document.createElement("li");
    const when = item.t === null || item.t === undefined ? "" : `t=${Number(item.t).toFixed(1)} `;
    li.textContent = when + item.text;
    recent.appendChild(li);
  }
  doorControls(s);
  const over = s.phase === "complete" || s.phase === "incomplete";
  for (const id of ["pause", "resume"]) $(id).disabled = over || s.mission_done;
  $("end").hidden = !(s.mission_done && !over);
}

function doorControls(s) {
  const box = $("door-controls");
  box.hidden = s.world !== "real";
  if (box.hidden) return;
  const doors = s.her_doors.length ? s.her_doors : Object.keys(s.doors);
  const wanted = doors.join(",");
  if (box.dataset.doors === wanted) return;
  box.dataset.doors = wanted;
  box.replaceChildren();
  for (const door of doors) {
    for (const open of [true, false]) {
      const b = document.createElement("button");
      b.type = "button";
      b.textContent = `${door}: ${open ? "opened" : "closed"}`;
      b.addEventListener("click", () => send("door", { door, open }));
      box.appendChild(b);
    }
  }
}

async function poll() {
  try {
    const response = await fetch("/api/state", { credentials: "same-origin", cache: "no-store" });
    if (!response.ok) throw new Error(`HTTP ${response.status}`);
    render(await response.json());
    $("link").title = "";
  } catch (err) {
    badge("link", "runner not reachable", "bad");
    $("link").title = String(err);
  } finally {
    setTimeout(poll, POLL_MS);
  }
}

async function send(command, body) {
  const answer = $("answer");
  answer.className = "answer";
  answer.textContent = `${command}…`;
  try {
    const response = await fetch(`/api/${command}`, {
      method: "POST",
      credentials: "same-origin",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify(body || {}),
    });
    const result = await response.json();
    if (!result.ok) throw new Error(result.error || `HTTP ${response.status}`);
    answer.textContent = `${command}: done`;
    return true;
  } catch (err) {
    answer.className = "answer bad";
    answer.textContent = `${command}: ${err.message}`;
    return false;
  }
}

document.addEventListener("DOMContentLoaded", () => {
  $("mark-form").addEventListener("submit", async (event) => {
    event.preventDefault();
    const note = $("mark-note").value.trim();
    if (note && (await send("mark", { note }))) $("mark-note").value = "";
  });
  $("pause").addEventListener("click", () => send("pause"));
  $("resume").addEventListener("click", () => send("resume"));
  $("abort-form").addEventListener("submit", async (event) => {
    event.preventDefault();
    const reason = $("abort-reason").value.trim();
    if (!reason) {
      $("answer").className = "answer bad";
      $("answer").textContent = "abort: say why (it is kept with the trial)";
      return;
    }
    if (window.confirm(`Abort ${state ? state.trial : "the trial"}? It will be marked incomplete.`)) {
      await send("abort", { reason });
    }
  });
  $("end").addEventListener("click", () => {
    if (window.confirm("End the trial without her questionnaire? It will be marked incomplete.")) send("end");
  });
  poll();
});
