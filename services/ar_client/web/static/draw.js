// Drawing on canvases: the Overlay's primitives over the camera image, and the top-down map.
//
// Primitives follow services/ar_client/draw.py (the same conventions as the server's own renderer):
// image pixels of the processed frame, RGBA colours, "polyline"/"line" stroked, "polygon" filled,
// "circle" stroked (filled when its width is 0), "arrow" = [tail, head], "text" with its baseline
// starting at the point and "radius" as its height; style "dashed", or "xray" (dashed, half
// opacity: hidden behind a wall).

const DASH = [10, 7];
const XRAY_ALPHA = 0.5;

function rgba(c, alpha = 1) {
  const a = (c.length > 3 ? c[3] / 255 : 1) * alpha;
  return `rgba(${c[0]},${c[1]},${c[2]},${a.toFixed(3)})`;
}

// Where an image of size (w, h) shows inside a box of (bw, bh) CSS pixels with object-fit: contain.
export function letterbox(w, h, bw, bh) {
  if (!w || !h || !bw || !bh) return null;
  const s = Math.min(bw / w, bh / h);
  return { x: (bw - w * s) / 2, y: (bh - h * s) / 2, s, w: w * s, h: h * s };
}

// Draw an overlay's primitives; `box` maps frame pixels to canvas pixels (x + u·s, y + v·s).
export function drawPrimitives(ctx, prims, box) {
  const { x, y, s } = box;
  const px = (p) => [x + p[0] * s, y + p[1] * s];
  for (const p of prims) {
    const xray = p.s === "xray";
    const alpha = xray ? XRAY_ALPHA : 1;
    ctx.save();
    ctx.strokeStyle = rgba(p.c, alpha);
    ctx.fillStyle = rgba(p.c, alpha);
    ctx.lineWidth = Math.max(1, (p.w || 1) * Math.max(s, 0.5));
    ctx.lineJoin = "round";
    ctx.lineCap = "round";
    if (xray || p.s === "dashed") ctx.setLineDash(DASH);
    const pts = p.p.map(px);
    if (p.k === "polyline" || p.k === "line") {
      if (pts.length >= 2) {
        ctx.beginPath();
        ctx.moveTo(...pts[0]);
        for (const q of pts.slice(1)) ctx.lineTo(...q);
        ctx.stroke();
      }
    } else if (p.k === "polygon") {
      if (pts.length >= 3) {
        ctx.beginPath();
        ctx.moveTo(...pts[0]);
        for (const q of pts.slice(1)) ctx.lineTo(...q);
        ctx.closePath();
        ctx.fill();
      }
    } else if (p.k === "circle") {
      if (pts.length >= 1) {
        ctx.beginPath();
        ctx.arc(pts[0][0], pts[0][1], Math.max(1, (p.r || 1) * s), 0, 2 * Math.PI);
        if (!p.w) ctx.fill(); else ctx.stroke();
      }
    } else if (p.k === "arrow") {
      if (pts.length >= 2) drawArrow(ctx, pts[0], pts[1]);
    } else if (p.k === "text") {
      if (pts.length >= 1 && p.t) {
        const size = Math.max(10, (p.r || 16) * s);
        ctx.setLineDash([]);
        ctx.font = `${size.toFixed(0)}px sans-serif`;
        ctx.lineWidth = Math.max(2, size / 6);
        ctx.strokeStyle = `rgba(0,0,0,${(0.6 * alpha).toFixed(2)})`;
        ctx.strokeText(p.t, pts[0][0], pts[0][1]);
        ctx.fillText(p.t, pts[0][0], pts[0][1]);
      }
    }
    ctx.restore();
  }
}

function drawArrow(ctx, tail, head) {
  const dx = head[0] - tail[0], dy = head[1] - tail[1];
  const len = Math.hypot(dx, dy);
  if (len < 1) return;
  const ux = dx / len, uy = dy / len;
  const tip = Math.min(len * 0.4, 12 + ctx.lineWidth * 2);
  ctx.beginPath();
  ctx.moveTo(...tail);
  ctx.lineTo(...head);
  ctx.moveTo(head[0] - tip * (ux - 0.5 * uy), head[1] - tip * (uy + 0.5 * ux));
  ctx.lineTo(...head);
  ctx.lineTo(head[0] - tip * (ux + 0.5 * uy), head[1] - tip * (uy - 0.5 * ux));
  ctx.stroke();
}

// ---------------------------------------------------------------------------- the map

const MAP = {
  room: "#f4f1ea", wall: "#3b3b3b", passage: "#2ca02c", open: "#3cc850", closed: "#e63c32",
  unknown: "#a0a0a0", landmark: "#7b3fb5", human: "#c2185b", tablet: "#1565c0",
};

// The camera's viewing direction in the world (third column of R_world_camera) from [x, y, z, w].
function viewDirection(q) {
  const [x, y, z, w] = q;
  return [2 * (x * z + w * y), 2 * (y * z - w * x)];
}

// A canvas sized to its box in device pixels, cleared, drawing in CSS pixels: [ctx, width, height].
export function clearCanvas(canvas) {
  const ctx = canvas.getContext("2d");
  const dpr = window.devicePixelRatio || 1;
  const cw = canvas.clientWidth, ch = canvas.clientHeight;
  if (canvas.width !== Math.round(cw * dpr) || canvas.height !== Math.round(ch * dpr)) {
    canvas.width = Math.round(cw * dpr);
    canvas.height = Math.round(ch * dpr);
  }
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, cw, ch);
  return [ctx, cw, ch];
}

// Draw the site top-down with the world state. `tablet` is an overlay with a pose, or null.
export function drawMap(canvas, site, world, tablet) {
  const [ctx, cw, ch] = clearCanvas(canvas);
  if (!site || !cw || !ch) return;
  const [x0, y0, x1, y1] = site.bounds;
  const margin = 16;
  const s = Math.min((cw - 2 * margin) / (x1 - x0), (ch - 2 * margin) / (y1 - y0));
  const ox = (cw - (x1 - x0) * s) / 2, oy = (ch - (y1 - y0) * s) / 2;
  const P = (x, y) => [ox + (x - x0) * s, ch - oy - (y - y0) * s];  // y up in the world, down on screen

  ctx.fillStyle = MAP.room;
  for (const [rx0, ry0, rx1, ry1] of Object.values(site.rooms)) {
    const [a, b] = P(rx0, ry1);
    ctx.fillRect(a, b, (rx1 - rx0) * s, (ry1 - ry0) * s);
  }
  ctx.fillStyle = "#666";
  ctx.font = "11px sans-serif";
  for (const [rid, [rx0, ry0, rx1, ry1]] of Object.entries(site.rooms)) {
    const [a, b] = P(rx0, ry1);
    ctx.fillText(rid, a + 4, b + 13);
  }
  line(ctx, MAP.wall, Math.max(2, 0.1 * s), site.walls.map(([ax, ay, bx, by]) => [P(ax, ay), P(bx, by)]));
  ctx.save();
  ctx.setLineDash([3, 3]);
  line(ctx, MAP.passage, 2, Object.values(site.passages).map(([a, b]) => [P(...a), P(...b)]));
  ctx.restore();
  for (const [did, d] of Object.entries(site.doors)) {
    const state = world && did in world.doors ? world.doors[did] : null;
    const colour = state === null ? MAP.unknown : (state ? MAP.open : MAP.closed);
    line(ctx, colour, Math.max(3, 0.08 * s), [[P(...d.hinge), P(...(state ? d.open : d.closed))]]);
    if (d.human_operated) {
      const [a, b] = P(...d.hinge);
      ctx.fillStyle = colour;
      ctx.fillText(`${did}${state === null ? "" : state ? " open" : " closed"}`, a + 4, b - 6);
    }
  }
  ctx.fillStyle = MAP.landmark;
  for (const [, lx, ly] of site.landmarks) {
    const [a, b] = P(lx, ly);
    ctx.fillRect(a - 1.5, b - 1.5, 3, 3);
  }
  // Where the human is: the simulator's word in a study (world.human), her desk otherwise.
  const [hx, hy] = P(...(world && world.human ? world.human.slice(0, 2) : site.human));
  dot(ctx, hx, hy, 6, MAP.human);

  if (world) {
    for (const [rid, path] of Object.entries(world.intents)) {
      const robot = world.robots[rid];
      const colour = robot && robot.color ? rgba(robot.color) : "#888";
      if (path.length >= 2) {
        const pts = path.map(([x, y]) => P(x, y));
        ctx.save();
        ctx.strokeStyle = colour;
        ctx.lineWidth = 2;
        ctx.beginPath();
        ctx.moveTo(...pts[0]);
        for (const q of pts.slice(1)) ctx.lineTo(...q);
        ctx.stroke();
        const end = pts[pts.length - 1];
        ctx.beginPath();
        ctx.arc(end[0], end[1], 5, 0, 2 * Math.PI);
        ctx.stroke();
        ctx.restore();
      }
    }
    for (const [rid, r] of Object.entries(world.robots)) {
      const [a, b] = P(r.x, r.y);
      const colour = r.color ? rgba(r.color) : "#888";
      dot(ctx, a, b, Math.max(4, site.robot_radius * s), colour);
      const len = Math.max(8, 2 * site.robot_radius * s);
      line(ctx, "#000", 2, [[[a, b], [a + len * Math.cos(r.theta), b - len * Math.sin(r.theta)]]]);
      ctx.fillStyle = "#111";
      ctx.fillText(r.state ? `${rid}: ${r.state.replaceAll("_", " ")}` : rid, a + 8, b - 8);
    }
  }
  if (tablet && tablet.ok && tablet.position.length === 3 && tablet.quaternion.length === 4) {
    const [a, b] = P(tablet.position[0], tablet.position[1]);
    const [dx, dy] = viewDirection(tablet.quaternion);
    const n = Math.hypot(dx, dy) || 1;
    const len = 24;
    line(ctx, MAP.tablet, 3, [[[a, b], [a + (len * dx) / n, b - (len * dy) / n]]]);
    dot(ctx, a, b, 5, MAP.tablet);
  }
}

function line(ctx, colour, width, segments) {
  ctx.strokeStyle = colour;
  ctx.lineWidth = width;
  ctx.lineCap = "butt";
  ctx.beginPath();
  for (const [a, b] of segments) {
    ctx.moveTo(...a);
    ctx.lineTo(...b);
  }
  ctx.stroke();
}

function dot(ctx, x, y, r, colour) {
  ctx.fillStyle = colour;
  ctx.beginPath();
  ctx.arc(x, y, r, 0, 2 * Math.PI);
  ctx.fill();
}
