// pheromone view: polls the view's API about ten times a second and draws the newest frame.
// Everything it drew is also written to the DOM (outputs with ids, data- attributes on the
// heat canvas) so that a test in a headless browser can read what the page shows.
"use strict";

const PERIOD_MS = 100;
const BOX_PX = 640;
const $ = (id) => document.getElementById(id);

// Viridis, sampled at nine stops and interpolated into a 256-entry table.
const STOPS = [
  [68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
  [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37],
];
const LUT = (() => {
  const lut = new Uint8ClampedArray(256 * 3);
  for (let i = 0; i < 256; i++) {
    const t = (i / 255) * (STOPS.length - 1);
    const k = Math.min(Math.floor(t), STOPS.length - 2);
    const f = t - k;
    for (let c = 0; c < 3; c++) {
      lut[i * 3 + c] = Math.round(STOPS[k][c] * (1 - f) + STOPS[k + 1][c] * f);
    }
  }
  return lut;
})();

// walls: the world's wall segments [x0, y0, x1, y1] (m) from /api/walls; null until read.
const state = { frame: null, robots: [], framesDrawn: 0, channels: 0, walls: null };

function fmt(v, digits = 4) {
  if (v === null || v === undefined || !Number.isFinite(v)) return "–";
  if (v !== 0 && (Math.abs(v) >= 1e5 || Math.abs(v) < 1e-3)) return v.toExponential(3);
  return Number(v.toPrecision(digits)).toString();
}

function scaleRange(frame) {
  if ($("scale-mode").value === "fixed") {
    const lo = parseFloat($("scale-min").value);
    const hi = parseFloat($("scale-max").value);
    if (Number.isFinite(lo) && Number.isFinite(hi) && hi > lo) return [lo, hi];
  }
  const lo = Math.min(0, frame.min);
  const hi = frame.max > lo ? frame.max : lo + 1;
  return [lo, hi];
}

// Canvas geometry: metres to overlay pixels, the grid's aspect kept.
function layout(frame) {
  const wm = frame.source_width * frame.source_cell_size_m;
  const hm = frame.source_height * frame.source_cell_size_m;
  const pxPerM = BOX_PX / Math.max(wm, hm);
  return { wm, hm, pxPerM, w: Math.round(wm * pxPerM), h: Math.round(hm * pxPerM) };
}

function drawFrame(frame) {
  const heat = $("heat");
  if (heat.width !== frame.width || heat.height !== frame.height) {
    heat.width = frame.width;
    heat.height = frame.height;
  }
  const g = layout(frame);
  for (const el of [$("canvas-box"), heat, $("overlay")]) {
    el.style.width = g.w + "px";
    el.style.height = g.h + "px";
  }
  const [lo, hi] = scaleRange(frame);
  const ctx = heat.getContext("2d", { willReadFrequently: true });
  const img = ctx.createImageData(frame.width, frame.height);
  let dmin = Infinity, dmax = -Infinity;
  for (let row = 0; row < frame.height; row++) {
    // Row 0 is the lowest y: drawn at the bottom.
    const out = (frame.height - 1 - row) * frame.width;
    for (let col = 0; col < frame.width; col++) {
      const v = frame.cells[row * frame.width + col];
      if (v < dmin) dmin = v;
      if (v > dmax) dmax = v;
      const t = Math.max(0, Math.min(1, (v - lo) / (hi - lo)));
      const k = Math.round(t * 255) * 3;
      const p = (out + col) * 4;
      img.data[p] = LUT[k];
      img.data[p + 1] = LUT[k + 1];
      img.data[p + 2] = LUT[k + 2];
      img.data[p + 3] = 255;
    }
  }
  ctx.putImageData(img, 0, 0);

  // What was drawn, for people and for tests.
  const hot = frame.hottest;
  const hc = Math.min(frame.width - 1, Math.floor(hot.col / frame.factor));
  const hr = Math.min(frame.height - 1, Math.floor(hot.row / frame.factor));
  const px = ctx.getImageData(hc, frame.height - 1 - hr, 1, 1).data;
  const pixel = `rgb(${px[0]}, ${px[1]}, ${px[2]})`;
  state.framesDrawn += 1;
  $("frame-seq").value = String(frame.sequence);
  $("frame-time").value = fmt(frame.sim_time_s, 6);
  $("frame-grid").value =
    `${frame.width}×${frame.height} of ${frame.source_width}×${frame.source_height}, ` +
    `cell ${fmt(frame.cell_size_m)} m, channel ${frame.channel}`;
  $("frame-min").value = fmt(dmin);
  $("frame-max").value = fmt(dmax);
  $("hot-value").value = fmt(hot.value);
  $("hot-x").value = fmt(hot.x_m);
  $("hot-y").value = fmt(hot.y_m);
  $("hot-pixel").value = pixel;
  $("frames-drawn").value = String(state.framesDrawn);
  Object.assign(heat.dataset, {
    seq: String(frame.sequence),
    channel: String(frame.channel),
    min: String(dmin),
    max: String(dmax),
    hotValue: String(hot.value),
    hotXM: String(hot.x_m),
    hotYM: String(hot.y_m),
    hotPixel: pixel,
    scaleMin: String(lo),
    scaleMax: String(hi),
  });

  // Axes in metres, colour bar in the field's units, a scale bar.
  $("x-min").textContent = fmt(frame.origin_x_m);
  $("x-max").textContent = fmt(frame.origin_x_m + g.wm);
  $("y-min").textContent = fmt(frame.origin_y_m);
  $("y-max").textContent = fmt(frame.origin_y_m + g.hm);
  $("x-axis").style.width = g.w + "px";
  $("bar").style.height = g.h + "px";
  $("bar-min").textContent = fmt(lo);
  $("bar-mid").textContent = fmt((lo + hi) / 2);
  $("bar-max").textContent = fmt(hi);
  const nice = niceLength(g.wm / 5);
  $("scale-bar-line").style.width = Math.round(nice * g.pxPerM) + "px";
  $("scale-bar-label").textContent = `${fmt(nice)} m`;
  drawOverlay(frame);
}

function niceLength(m) {
  const p = Math.pow(10, Math.floor(Math.log10(m)));
  for (const k of [5, 2, 1]) if (k * p <= m) return k * p;
  return p;
}

function drawColourBar() {
  const bar = $("bar");
  const ctx = bar.getContext("2d");
  for (let i = 0; i < 256; i++) {
    ctx.fillStyle = `rgb(${LUT[i * 3]}, ${LUT[i * 3 + 1]}, ${LUT[i * 3 + 2]})`;
    ctx.fillRect(0, 255 - i, bar.width, 1);
  }
}

// By robot id, as in the pictures of a run (report's style.rs): its five fixed colours, then
// golden-ratio hue steps.
const ROBOT_COLOURS = ["rgb(240, 40, 40)", "rgb(0, 170, 240)", "rgb(255, 150, 0)",
  "rgb(230, 90, 190)", "rgb(150, 110, 255)"];
function robotColour(id) {
  if (id < ROBOT_COLOURS.length) return ROBOT_COLOURS[id];
  return `hsl(${Math.round(((id * 0.618033988749895) % 1) * 360)}, 90%, 55%)`;
}
// Walls, as in the pictures (report's WALL_RGB).
const WALL_COLOUR = "rgb(215, 215, 215)";

// The walls on the overlay, 3 px wide; the number drawn and the colour read back at the middle
// of the first one inside the canvas go on the canvas' data- attributes (for tests).
function drawWalls(ctx, frame, g, X, Y) {
  const walls = state.walls || [];
  ctx.strokeStyle = WALL_COLOUR;
  ctx.lineWidth = 3;
  ctx.beginPath();
  for (const [x0, y0, x1, y1] of walls) {
    ctx.moveTo(X(x0), Y(y0));
    ctx.lineTo(X(x1), Y(y1));
  }
  ctx.stroke();
  const ov = $("overlay");
  ov.dataset.walls = String(walls.length);
  const inside = walls.find(([x0, y0, x1, y1]) => {
    const [mx, my] = [(X(x0) + X(x1)) / 2, (Y(y0) + Y(y1)) / 2];
    return mx >= 0 && my >= 0 && mx <= g.w && my <= g.h;
  });
  if (inside) {
    const [x0, y0, x1, y1] = inside;
    const mx = Math.min(g.w - 1, Math.floor((X(x0) + X(x1)) / 2));
    const my = Math.min(g.h - 1, Math.floor((Y(y0) + Y(y1)) / 2));
    const px = ctx.getImageData(mx, my, 1, 1).data;
    ov.dataset.wallPixel = `rgb(${px[0]}, ${px[1]}, ${px[2]})`;
  }
}

function drawOverlay(frame) {
  const ov = $("overlay");
  const g = layout(frame);
  if (ov.width !== g.w || ov.height !== g.h) {
    ov.width = g.w;
    ov.height = g.h;
  }
  const ctx = ov.getContext("2d");
  ctx.clearRect(0, 0, ov.width, ov.height);
  const X = (x) => (x - frame.origin_x_m) * g.pxPerM;
  const Y = (y) => g.h - (y - frame.origin_y_m) * g.pxPerM;
  drawWalls(ctx, frame, g, X, Y);
  state.robots.forEach((r) => {
    const colour = robotColour(r.id);
    ctx.strokeStyle = colour;
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    r.path.forEach(([x, y], k) => (k ? ctx.lineTo(X(x), Y(y)) : ctx.moveTo(X(x), Y(y))));
    ctx.stroke();
    // The pose: a triangle pointing along the heading.
    const [cx, cy, th] = [X(r.x_m), Y(r.y_m), r.theta_rad];
    ctx.fillStyle = colour;
    ctx.beginPath();
    ctx.moveTo(cx + 9 * Math.cos(th), cy - 9 * Math.sin(th));
    ctx.lineTo(cx + 5 * Math.cos(th + 2.4), cy - 5 * Math.sin(th + 2.4));
    ctx.lineTo(cx + 5 * Math.cos(th - 2.4), cy - 5 * Math.sin(th - 2.4));
    ctx.closePath();
    ctx.fill();
    ctx.fillText(`r${r.id}`, cx + 8, cy - 8);
  });
}

function showStats(s) {
  $("stat-tick-hz").value = fmt(s.tick_hz);
  $("stat-tick-ms").value = fmt(s.tick_compute_ms);
  $("stat-gap-ms").value = fmt(s.longest_tick_gap_ms);
  $("stat-applied").value = String(s.deposits_applied);
  $("stat-rejected").value = String(s.deposits_rejected_total);
  $("stat-readers").value = s.readers === null ? "–" : String(s.readers);
  $("rejected-by-reason").innerHTML = Object.entries(s.deposits_rejected)
    .map(([k, v]) => `<tr><th>${k}</th><td>${v}</td></tr>`).join("");
  if (s.channels !== state.channels && s.channels > 0) {
    state.channels = s.channels;
    const sel = $("channel");
    const keep = sel.value;
    sel.innerHTML = "";
    for (let c = 0; c < s.channels; c++) sel.add(new Option(String(c), String(c)));
    sel.value = Number(keep) < s.channels ? keep : "0";
  }
}

function showRobots(answer) {
  state.robots = answer.robots;
  $("robots-count").value = String(answer.robots.length);
  $("robots-world").textContent = answer.world ? `in world ${answer.world}` : "(no --world given)";
  $("robots").innerHTML = answer.robots
    .map((r) => `<li>r${r.id}: (${fmt(r.x_m)}, ${fmt(r.y_m)}) m, step ${r.step}</li>`).join("");
}

function setStatus(stateName, text) {
  const el = $("status");
  el.dataset.state = stateName;
  el.textContent = text;
}

async function getJson(path) {
  const r = await fetch(path, { cache: "no-store" });
  if (!r.ok) throw new Error(`${path}: ${r.status} ${await r.text()}`);
  return r.json();
}

async function tick() {
  const started = performance.now();
  try {
    // The field's state first: before it starts there is no frame to ask for.
    const stats = await getJson("/api/stats");
    showStats(stats);
    if (state.walls === null) state.walls = (await getJson("/api/walls")).walls;
    if (stats.state !== "waiting") {
      const q = `channel=${$("channel").value}&max_side=${$("max-side").value}`;
      const [frame, robots] = await Promise.all([
        getJson(`/api/frame?${q}`), getJson("/api/robots"),
      ]);
      state.robots = robots.robots;
      showRobots(robots);
      state.frame = frame;
      drawFrame(frame);
    }
    // waiting, live, stalled or stopped, in the view's words.
    setStatus(stats.state, stats.status);
  } catch (e) {
    setStatus("error", String(e.message || e));
  }
  setTimeout(tick, Math.max(0, PERIOD_MS - (performance.now() - started)));
}

$("scale-mode").addEventListener("change", () => {
  const fixed = $("scale-mode").value === "fixed";
  $("scale-min").disabled = !fixed;
  $("scale-max").disabled = !fixed;
  if (fixed && state.frame) {
    $("scale-min").value = fmt(Math.min(0, state.frame.min));
    $("scale-max").value = fmt(state.frame.max);
  }
});
drawColourBar();
tick();
