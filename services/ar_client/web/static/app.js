// The tablet page: connects to the server, runs the camera (AR mode) or shows the sim's stream
// (viewer mode), draws each frame's overlay over the live picture, the map, and the feedback panel.
// On a study server (arroch tablet --study-trial) the hello carries the trial, and study.js turns
// the page into the study page of its condition (the server then sets the mode: viewer, or map).
//
// Honesty rules of the display: world geometry is drawn only from an overlay computed for a recent
// frame (older than STALE_MS: hidden, and the status says so); "LOST" is shown with the age of the
// last pose and the reason; link latency is the measured round trip of the last frames.

import { clearCanvas, drawMap, drawPrimitives, letterbox } from "./draw.js";
import { GravitySource } from "./gravity.js";
import { FrameSender, parseViewerFrame } from "./link.js";
import { FeedbackPanel } from "./panel.js";
import { StudyPage } from "./study.js";

const STALE_MS = 1000;
const MAX_SAMPLES = 5000;

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const token = params.get("token");
const askedMode = ["ar", "viewer"].includes(params.get("mode")) ? params.get("mode") : null;
const earlyQuestionnaire = params.get("questionnaire") === "1"; // study: the experimenter opens it early

const state = {
  ws: null,
  connected: false,
  hello: null,
  mode: askedMode || "ar",
  world: null,
  overlay: null,
  overlayAt: 0,
  stale: false,
  camera: "off", // off | starting | on | failed
  cameraError: "",
  stream: { frames: 0, size: [0, 0], pending: new Map() },
  samples: [],
  overlays: 0,
  showMap: false,
  requestId: 0,
  reconnectDelay: 500,
};

const gravity = new GravitySource();
const sender = new FrameSender(() => state.ws, { getGravity: () => gravity.current() });
// iOS gives motion data only after the user allowed it, from a tap.
window.addEventListener("pointerdown", () => gravity.ask(), { once: true });
const panel = new FeedbackPanel($("entries"), sendFeedback);
const study = new StudyPage({ send, early: earlyQuestionnaire });

// ------------------------------------------------------------------------------- connection

function socketUrl() {
  const url = new URL("/ws", location.href);
  url.protocol = location.protocol === "https:" ? "wss:" : "ws:";
  if (token) url.searchParams.set("token", token);
  if (askedMode) url.searchParams.set("mode", askedMode);
  if (earlyQuestionnaire) url.searchParams.set("questionnaire", "1");
  return url.toString();
}

function connect() {
  setPill("conn", "connecting…", "warn");
  const ws = new WebSocket(socketUrl());
  ws.binaryType = "arraybuffer";
  state.ws = ws;
  ws.onopen = () => {
    state.connected = true;
    state.reconnectDelay = 500;
    setPill("conn", "connected", "ok");
  };
  ws.onmessage = (event) => {
    if (typeof event.data === "string") onText(JSON.parse(event.data));
    else onBinary(event.data);
  };
  ws.onclose = (event) => {
    state.connected = false;
    state.ws = null;
    panel.onDisconnect();
    const why = event.code === 1006 ? "refused or unreachable" : `${event.code}${event.reason ? " " + event.reason : ""}`;
    setPill("conn", `disconnected (${why}); retrying`, "bad");
    setTimeout(connect, state.reconnectDelay);
    state.reconnectDelay = Math.min(10000, state.reconnectDelay * 2);
  };
}

function send(obj) {
  if (!state.ws || state.ws.readyState !== WebSocket.OPEN) return false;
  state.ws.send(JSON.stringify(obj));
  return true;
}

function sendFeedback(kind, values) {
  const id = ++state.requestId;
  return send({ type: "feedback", id, kind, params: values, wall: Date.now() / 1000 }) ? id : null;
}

function onText(msg) {
  switch (msg.type) {
    case "hello": return onHello(msg);
    case "overlay": return onOverlay(msg);
    case "world":
      state.world = msg;
      panel.setNow(msg.now);
      if (state.hello && state.hello.study) study.onWorld(msg);
      return renderMap();
    case "constraints": return panel.setConstraints(msg.items);
    case "library": return panel.setLibrary(msg.entries);
    case "ack": return panel.onAck(msg);
    case "study": return study.onState(msg);
    case "refused": return study.onRefused(msg);
    default: return undefined;
  }
}

function onHello(msg) {
  state.hello = msg;
  state.mode = msg.mode;
  state.world = msg.world;
  sender.maxFps = msg.max_fps;
  sender.maxSide = msg.max_side;
  sender.maxBytes = msg.max_frame_bytes;
  document.body.dataset.mode = state.mode;
  $("toggle-mode").textContent = state.mode === "ar" ? "Viewer" : "Camera";
  panel.setNow(msg.world.now);
  panel.setLibrary(msg.library);
  panel.setConstraints(msg.constraints.items);
  if (msg.study) study.start(msg);
  renderMap();
  if (state.mode === "ar") startCamera();
  else if (state.mode === "viewer") notice(msg.stream ? "" : "No sim camera on this server (start it with --camera-source sim:CID): map only.");
}

// ------------------------------------------------------------------------------- camera (AR mode)

async function startCamera() {
  if (state.camera === "on" || state.camera === "starting") return;
  if (!navigator.mediaDevices || !navigator.mediaDevices.getUserMedia) {
    state.camera = "failed";
    notice("This browser offers no camera on this page (it needs HTTPS). Use the viewer mode.");
    return;
  }
  state.camera = "starting";
  try {
    const stream = await navigator.mediaDevices.getUserMedia({
      audio: false,
      video: { facingMode: { ideal: "environment" }, width: { ideal: 1280 }, height: { ideal: 720 }, resizeMode: { ideal: "none" } },
    });
    const video = $("video");
    video.srcObject = stream;
    await video.play().catch(() => {});
    state.camera = "on";
    notice("");
    sender.start(video);
  } catch (err) {
    state.camera = "failed";
    state.cameraError = String(err && err.message ? err.message : err);
    notice(`No camera: ${state.cameraError}. Allow the camera, or use the viewer mode.`);
  }
}

// ------------------------------------------------------------------------------- overlays

function onOverlay(msg) {
  let timing = null;
  if (msg.source === "sim") {
    const frame = state.stream.pending.get(msg.seq);
    state.stream.pending.delete(msg.seq);
    if (frame) frame.then((bitmap) => showStreamFrame(bitmap, msg));
    return;
  }
  timing = sender.answered(msg.seq);
  countAnswer();
  accept(msg);
  const drawn = performance.now();
  if (timing) {
    state.samples.push({ seq: msg.seq, capture_to_drawn: drawn - timing.captured, sent_to_drawn: drawn - timing.sent,
      server_ms: msg.server_ms, width: timing.w, height: timing.h, bytes: timing.bytes, ok: msg.ok });
    if (state.samples.length > MAX_SAMPLES) state.samples.splice(0, state.samples.length - MAX_SAMPLES);
  }
  updateLink();
}

function accept(msg) {
  state.overlay = msg;
  state.overlayAt = performance.now();
  state.stale = false;
  state.overlays += 1;
  renderOverlay();
  updatePose();
  renderMap();
}

function sourceSize() {
  if (state.mode === "viewer") return state.stream.size;
  const video = $("video");
  return [video.videoWidth, video.videoHeight];
}

function renderOverlay() {
  const canvas = $("overlay");
  const [ctx, cw, ch] = clearCanvas(canvas);
  const o = state.overlay;
  if (!o || state.stale || !o.width) return;
  // The frame was a scaled copy of the picture on screen: map its pixels onto the displayed picture.
  const [sw, sh] = sourceSize();
  const box = letterbox(sw || o.width, sh || o.height, cw, ch);
  if (!box) return;
  // Nothing outside the picture: primitives may reach one image size beyond the frame.
  ctx.save();
  ctx.beginPath();
  ctx.rect(box.x, box.y, box.w, box.h);
  ctx.clip();
  drawPrimitives(ctx, o.primitives, { x: box.x, y: box.y, s: box.w / o.width });
  ctx.restore();
}

function showStreamFrame(bitmap, msg) {
  const canvas = $("stream");
  if (canvas.width !== bitmap.width || canvas.height !== bitmap.height) {
    canvas.width = bitmap.width;
    canvas.height = bitmap.height;
  }
  canvas.getContext("2d").drawImage(bitmap, 0, 0);
  bitmap.close();
  state.stream.size = [canvas.width, canvas.height];
  state.stream.frames += 1;
  countAnswer();
  accept(msg);
  updateLink();
}

function onBinary(buffer) {
  const frame = parseViewerFrame(buffer);
  if (!frame) return;
  const [seq, jpeg] = frame;
  // Decoding runs while the overlay is on its way; the two are shown together.
  state.stream.pending.set(seq, createImageBitmap(new Blob([jpeg], { type: "image/jpeg" })));
  if (state.stream.pending.size > 4) state.stream.pending.delete(state.stream.pending.keys().next().value);
}

// ------------------------------------------------------------------------------- status

function setPill(id, text, level) {
  const pill = $(id);
  pill.textContent = text;
  pill.className = `pill ${level}`;
}

function notice(text) {
  $("notice").textContent = text;
  $("notice").hidden = !text;
}

function updatePose() {
  const o = state.overlay;
  if (!o) return setPill("pose", "pose: waiting for the first overlay", "warn");
  if (state.stale) {
    const age = (performance.now() - state.overlayAt) / 1000;
    return setPill("pose", `no overlay for ${age.toFixed(1)} s`, "warn");
  }
  if (o.ok) {
    const n = o.tags.length;
    return setPill("pose", `pose: ${n} tag${n === 1 ? "" : "s"}, RMSE ${o.rmse.toFixed(2)} px`, o.rmse > 1.5 ? "warn" : "ok");
  }
  const age = o.lost_age > 0 ? `last pose ${o.lost_age.toFixed(1)} s ago` : "no pose yet";
  return setPill("pose", `LOST (${age})${o.reason ? ": " + o.reason : ""}`, "bad");
}

const answeredAt = []; // arrival times of the last 2 s of overlays, for the frame rate shown

function countAnswer() {
  const now = performance.now();
  answeredAt.push(now);
  while (answeredAt.length && now - answeredAt[0] > 2000) answeredAt.shift();
}

function updateLink() {
  const fps = answeredAt.length / 2;
  if (state.mode === "viewer") {
    const [w, h] = state.stream.size;
    return setPill("link", `stream ${w}x${h} · ${fps.toFixed(1)} fps`, "ok");
  }
  if (sender.rtt === null) return setPill("link", "link: –", "warn");
  const [w, h] = sender.size;
  const rtt = sender.rtt;
  return setPill("link", `link ${rtt.toFixed(0)} ms · ${fps.toFixed(1)} fps · ${w}x${h}`, rtt > 300 ? "bad" : rtt > 150 ? "warn" : "ok");
}

// Staleness is checked on every animation frame: the overlay is hidden once it is too old.
function watch() {
  if (state.overlay && !state.stale && performance.now() - state.overlayAt > STALE_MS) {
    state.stale = true;
    renderOverlay();
  }
  if (state.stale) updatePose();
  requestAnimationFrame(watch);
}

function renderMap() {
  if (!state.hello) return;
  const tablet = state.overlay && !state.stale ? state.overlay : null;
  if (state.mode !== "ar" || state.showMap) drawMap($("map"), state.hello.site, state.world, tablet);
}

// ------------------------------------------------------------------------------- controls

$("toggle-map").addEventListener("click", () => {
  state.showMap = !state.showMap;
  document.body.classList.toggle("with-map", state.showMap);
  renderMap();
});

$("toggle-mode").addEventListener("click", () => {
  const url = new URL(location.href);
  url.searchParams.set("mode", state.mode === "ar" ? "viewer" : "ar");
  location.assign(url.toString());
});

window.addEventListener("resize", () => {
  renderOverlay();
  renderMap();
});

// What tests and the latency benchmark read (the page's own measurements).
window.arroch = {
  stats: () => ({
    sent: sender.sent, overlays: state.overlays, given_up: sender.givenUp, scale: sender.scale, quality: sender.quality,
    rtt_ms: sender.rtt, size: sender.size, samples: state.samples.slice(),
  }),
  state: () => ({
    connected: state.connected, mode: state.mode, camera: state.camera, camera_error: state.cameraError,
    client: state.hello ? state.hello.client : null, stale: state.stale, stream_frames: state.stream.frames,
    overlay: state.overlay ? { seq: state.overlay.seq, ok: state.overlay.ok, tags: state.overlay.tags, rmse: state.overlay.rmse,
      width: state.overlay.width, height: state.overlay.height, primitives: state.overlay.primitives.length,
      reason: state.overlay.reason, intrinsics: state.overlay.intrinsics, position: state.overlay.position,
      gravity: state.overlay.gravity } : null,
    gravity: gravity.current(), gravity_source: gravity.kind,
    video: [$("video").videoWidth, $("video").videoHeight],
    robots: state.world ? Object.keys(state.world.robots) : [],
    // What the robots' view shows of each robot's state (a person sees "waiting at the door" there).
    robot_states: state.world ? Object.fromEntries(Object.entries(state.world.robots).map(([k, r]) => [k, r.state])) : {},
    acks: panel.results.slice(),
  }),
  study: () => (state.hello && state.hello.study ? study.snapshot() : null),
};

notice("");
connect();
requestAnimationFrame(watch);
