// Sending camera frames to the server, adapted to the link.
//
// - At most one frame in flight: the next frame is captured only when the previous one's overlay
//   came back (or was given up after GIVE_UP_MS), so frames never queue up in the network and every
//   overlay answers a recent picture.
// - At most `maxFps` frames per second (the server's limit, 15 by default).
// - Each frame carries the device's gravity at capture (gravity.js), NaN when unknown.
// - Size and JPEG quality follow the round trip: when its running average grows past SLOW_MS the
//   frames shrink (and lose some quality), when it stays under FAST_MS they grow back.
// The <video> element shows the camera itself, so none of this ever delays the live picture.

const MAGIC = [0x41, 0x52, 0x46, 0x32]; // "ARF2": seq, then gravity (3 float32, NaN when unknown), then the JPEG
const HEADER = 20;
const GIVE_UP_MS = 2000;
const SLOW_MS = 180;
const FAST_MS = 90;
const MIN_SCALE = 0.25;
const MIN_WIDTH = 240;
const STEP = 0.8;

export class FrameSender {
  constructor(getSocket, { maxFps = 15, maxSide = 1920, maxBytes = 2 * 1024 * 1024, startSide = 1280, getGravity = () => null } = {}) {
    this.getSocket = getSocket;
    this.getGravity = getGravity; // gravity in the camera frame at capture (gravity.js), or null
    this.maxFps = maxFps;
    this.maxSide = maxSide;
    this.maxBytes = maxBytes;
    this.startSide = startSide;
    this.scale = 1;
    this.quality = 0.8;
    this.seq = 0;
    this.inFlight = null;
    this.lastStart = -Infinity; // when the last frame was grabbed: the frame-rate limit counts from there
    this.lastChange = 0;
    this.rtt = null; // running average, ms
    this.sent = 0;
    this.givenUp = 0;
    this.size = [0, 0];
    this.canvas = document.createElement("canvas");
    this.ctx = this.canvas.getContext("2d", { alpha: false });
    this.timer = null;
    this.running = false;
  }

  start(video) {
    this.video = video;
    this.running = true;
    this.schedule(0);
  }

  stop() {
    this.running = false;
    clearTimeout(this.timer);
  }

  schedule(delay) {
    clearTimeout(this.timer);
    if (this.running) this.timer = setTimeout(() => this.tick(), Math.max(0, delay));
  }

  async tick() {
    if (!this.running || this.busy) return;
    const now = performance.now();
    if (this.inFlight && now - this.inFlight.sent > GIVE_UP_MS) {
      this.givenUp += 1; // lost, or the server is stuck: try again, smaller
      this.inFlight = null;
      this.shrink(now);
    }
    const ws = this.getSocket();
    const video = this.video;
    if (!ws || ws.readyState !== WebSocket.OPEN || !video || video.readyState < 2 || !video.videoWidth) return this.schedule(100);
    if (this.inFlight) return this.schedule(GIVE_UP_MS - (now - this.inFlight.sent) + 1);
    if (ws.bufferedAmount > 0) return this.schedule(10);
    const due = this.lastStart + 1000 / this.maxFps - now;
    if (due > 0) return this.schedule(due);
    this.busy = true;
    try {
      await this.send(ws, video);
    } finally {
      this.busy = false;
    }
    if (!this.inFlight) this.schedule(50);
  }

  async send(ws, video) {
    const vw = video.videoWidth, vh = video.videoHeight;
    const s = Math.min(this.scale * Math.min(1, this.startSide / Math.max(vw, vh)), this.maxSide / Math.max(vw, vh));
    const w = Math.max(16, Math.round(vw * s)), h = Math.max(16, Math.round(vh * s));
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.canvas.width = w;
      this.canvas.height = h;
    }
    const captured = (this.lastStart = performance.now());
    this.ctx.drawImage(video, 0, 0, w, h);
    const gravity = this.getGravity(); // read at capture, not after the JPEG encoding
    const blob = await new Promise((resolve) => this.canvas.toBlob(resolve, "image/jpeg", this.quality));
    if (!blob) return;
    if (blob.size > this.maxBytes) {
      this.shrink(performance.now());
      return;
    }
    const body = new Uint8Array(await blob.arrayBuffer());
    const seq = (this.seq = (this.seq + 1) >>> 0);
    const message = new Uint8Array(HEADER + body.length);
    message.set(MAGIC, 0);
    const view = new DataView(message.buffer);
    view.setUint32(4, seq, true);
    for (let i = 0; i < 3; i++) view.setFloat32(8 + 4 * i, gravity ? gravity[i] : NaN, true);
    message.set(body, HEADER);
    if (ws.readyState !== WebSocket.OPEN) return;
    ws.send(message.buffer);
    const sent = performance.now();
    this.inFlight = { seq, captured, sent, w, h, bytes: body.length, gravity };
    this.sent += 1;
    this.size = [w, h];
  }

  // The overlay for `seq` arrived: the timing record of its frame (null if not the one in flight).
  answered(seq) {
    const f = this.inFlight;
    if (!f || f.seq !== seq) return null;
    this.inFlight = null;
    const now = performance.now();
    const rtt = now - f.sent;
    this.rtt = this.rtt === null ? rtt : 0.8 * this.rtt + 0.2 * rtt;
    if (this.rtt > SLOW_MS) this.shrink(now);
    else if (this.rtt < FAST_MS) this.grow(now);
    this.schedule(0);
    return f;
  }

  shrink(now) {
    if (now - this.lastChange < 1000) return;
    const minScale = Math.max(MIN_SCALE, MIN_WIDTH / Math.max(1, this.size[0] / this.scale));
    if (this.scale > minScale) this.scale = Math.max(minScale, this.scale * STEP);
    this.quality = Math.max(0.5, this.quality - 0.1);
    this.lastChange = now;
  }

  grow(now) {
    if (now - this.lastChange < 3000 || (this.scale >= 1 && this.quality >= 0.8)) return;
    this.scale = Math.min(1, this.scale / STEP);
    this.quality = Math.min(0.8, this.quality + 0.1);
    this.lastChange = now;
  }
}

// A viewer-mode frame from the server: [seq, JPEG bytes], or null if it is not one.
export function parseViewerFrame(buffer) {
  const bytes = new Uint8Array(buffer);
  if (bytes.length < 8 || bytes[0] !== 0x41 || bytes[1] !== 0x52 || bytes[2] !== 0x56 || bytes[3] !== 0x31) return null;
  return [new DataView(buffer).getUint32(4, true), bytes.subarray(8)];
}
