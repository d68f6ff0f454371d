// Live tracking plots from the telemetry WebSocket: per axis goal vs measured, and the error.
// plotly.js (served by the app from the plotly package) draws. Speed matters at >= 20
// frames/s: a full Plotly.react costs 45-150 ms on a loaded 2-core machine, its
// animate(redraw: false) path about 20 ms, so frames use animate with fixed axes (time
// relative to now, y ranges with hysteresis) and a full redraw only when a range must change.
// Ring buffers hold a fixed 60 s (the longest window), so an hour-long session stays as fast
// as the first minute; windows over 10 s draw every n-th sample (at most ~600 per trace).
//
// Reading the plots (plotly's own zoom, hover and image export; pause is ours):
// - Pause freezes what is drawn and does no work while paused: incoming samples are dropped
//   (counted in plotStats.dropped), nothing is drawn; Resume continues with a gap in the lines.
// - Drag across a plot selects a time range (the x axes are matched; y stays fitted to the
//   data shown): zooming pauses; double-click restores the whole window (and resumes when
//   the zoom paused it).
// - The cursor: a vertical line (plotly spikes) and, under the plots, the value of every
//   series at the hovered time (the nearest drawn sample).
// - Snapshot: the plots as a PNG file (Plotly.toImage), as shown (paused, zoomed).
// - The time window: 5, 10, 30 or 60 s.

import { telemetryUrl, promptToken, token } from "./api.js";
import { phiSample, startPhiPlot } from "./phiplot.js";
import { Ring } from "./ring.js";

const HZ = 50;
const WINDOWS_S = [5, 10, 30, 60];
const CAPACITY = HZ * WINDOWS_S[WINDOWS_S.length - 1] + 100; // slack for rate jitter
const MAX_POINTS = 600; // per trace and frame: longer windows draw every n-th sample
const FRAME_MS = 33; // aim at 30 frames/s: headroom above the 20 the operator needs
const MIN_SPAN_MM = [2, 0.2]; // position, error: a resting signal does not zoom into noise
const AXES = ["x", "y", "z"];
const KINDS = ["goal", "measured", "error"];
const STYLE = {
  goal: { color: "#8a94a6", width: 2, dash: "dot" },
  measured: { color: "#2f7de1", width: 1.5 },
  error: { color: "#d9480f", width: 1.5 },
};
const CONFIG = { displayModeBar: false, responsive: true, doubleClick: false };

const series = { t: new Ring(CAPACITY) };
for (const a of AXES) for (const k of KINDS) series[`${k}_${a}`] = new Ring(CAPACITY);

// Exposed for the browser test and for anyone curious in the console.
export const plotStats = {
  samples: 0, frames: 0, fullDraws: 0, fps: 0, drawMs: 0, connected: false,
  dropped: 0, paused: false, windowS: 10, zoom: null,
  pausedDraws: 0, // draws begun while paused: after a pause, the one that fixes what is shown
};
window.deltadashPlot = plotStats;

let dirty = false;
let drawing = false;
let lastFrame = 0;
let lastT = -Infinity;
let ranges = null; // [6][2] y ranges in force, null before the first full draw
let fpsWindow = { start: performance.now(), frames: 0 };
let windowS = 10;
let paused = false;
let pausedByZoom = false;
let gapNext = false; // the first sample after a pause starts a new line
let zoom = null; // [t0, t1] the selected time range (s, relative to the last sample), or null
let relayoutNeeded = false; // a full redraw of the shown data (window, zoom, pause changed)
let shown = null; // { x, y: [9][] } the data on screen (the cursor reads it)

// Trace order: per axis i, goal and measured on subplot i + 1, error on subplot i + 4.
function traceKeys() {
  return AXES.flatMap((a, i) => KINDS.map((k) => ({ key: `${k}_${a}`, kind: k, plot: k === "error" ? i + 4 : i + 1 })));
}
const TRACES = traceKeys();

function stride() {
  return Math.max(1, Math.ceil((windowS * HZ) / MAX_POINTS));
}

// The samples of the window, every stride-th one counted from the first ever received (so
// a decimated line does not shimmer from frame to frame); null for unknown values.
function frameData() {
  const t = series.t.view();
  let first = t.length;
  while (first > 0 && t[first - 1] >= lastT - windowS - 0.1) first -= 1; // t is ascending
  const step = stride();
  const offset = plotStats.samples - t.length; // absolute index of t[0]
  first += (step - ((offset + first) % step)) % step;
  const pick = [];
  for (let i = first; i < t.length; i += step) pick.push(i);
  const x = pick.map((i) => t[i] - lastT);
  const y = TRACES.map(({ key }) => {
    const v = series[key].view();
    return pick.map((i) => (Number.isNaN(v[i]) ? null : v[i]));
  });
  return { x, y };
}

function asTraces(data) {
  return TRACES.map((_, i) => ({ x: data.x, y: data.y[i] }));
}

function fullTraces(data) {
  return TRACES.map(({ kind, plot }, i) => ({
    x: data.x, y: data.y[i], type: "scatter", mode: "lines", hoverinfo: "none", name: kind, line: STYLE[kind],
    xaxis: `x${plot}`, yaxis: `y${plot}`, showlegend: plot === 1 || (plot === 4 && kind === "error"),
  }));
}

function xRange() {
  return zoom ? [...zoom] : [-windowS, 0];
}

function layout() {
  const base = {
    margin: { l: 52, r: 8, t: 8, b: 30 }, showlegend: true, dragmode: "zoom", hovermode: "x",
    grid: { rows: 2, columns: 3, pattern: "independent", roworder: "top to bottom" },
    legend: { orientation: "h", x: 1, xanchor: "right", y: 1.0, yanchor: "bottom", bgcolor: "rgba(0,0,0,0)" },
    font: { family: "system-ui, sans-serif", size: 11 }, paper_bgcolor: "#fff", plot_bgcolor: "#fff",
  };
  for (let n = 1; n <= 6; n++) {
    const suffix = n === 1 ? "" : n;
    base[`xaxis${suffix}`] = { range: xRange(), gridcolor: "#eef0f3", zeroline: false,
      matches: n === 1 ? undefined : "x",
      title: n > 3 ? { text: "t − now [s]", standoff: 2 } : undefined };
    const label = n <= 3 ? `${AXES[n - 1]} [mm]` : `error ${AXES[n - 4]} [mm]`;
    base[`yaxis${suffix}`] = { range: ranges[n - 1], title: { text: label, standoff: 4 }, fixedrange: true,
      gridcolor: "#eef0f3", zerolinecolor: "#c9ced6", tickformat: "~r" };
  }
  return base;
}

// The y range each subplot needs for the samples inside the x range now, padded; null where
// it has no data.
function neededRanges(data) {
  const [lo_t, hi_t] = xRange();
  const out = [];
  for (let n = 1; n <= 6; n++) {
    let lo = Infinity, hi = -Infinity;
    data.y.forEach((ys, i) => {
      if (TRACES[i].plot !== n) return;
      ys.forEach((v, j) => {
        if (v !== null && data.x[j] >= lo_t && data.x[j] <= hi_t) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
      });
    });
    out.push(lo > hi ? null : [lo, hi]);
  }
  return out;
}

// Keep a range while the data fits and fills a fair part of it; else re-fit with headroom.
function updateRanges(data) {
  const needed = neededRanges(data);
  let changed = ranges === null;
  const next = needed.map((need, i) => {
    const current = ranges ? ranges[i] : [-1, 1];
    if (need === null) return current;
    const minSpan = MIN_SPAN_MM[i < 3 ? 0 : 1];
    const span = Math.max(need[1] - need[0], minSpan);
    const fits = need[0] >= current[0] && need[1] <= current[1];
    if (fits && current[1] - current[0] <= 4 * span) return current;
    changed = true;
    const mid = (need[0] + need[1]) / 2;
    return [mid - 0.8 * span, mid + 0.8 * span];
  });
  ranges = next;
  return changed;
}

async function render() {
  const wasPaused = paused;
  const data = paused && shown ? shown : frameData();
  const begin = performance.now();
  const full = relayoutNeeded;
  relayoutNeeded = false;
  if (updateRanges(data) || full) {
    await window.Plotly.react("plot", fullTraces(data), layout(), CONFIG);
    hookEvents();
    plotStats.fullDraws += 1;
    if (cursorT !== null) placeCursor(cursorT); // a new layout (margins, range) moves the time's pixel
  } else {
    await window.Plotly.animate("plot", { data: asTraces(data), traces: TRACES.map((_, i) => i) },
      { transition: { duration: 0 }, frame: { duration: 0, redraw: false }, mode: "immediate" });
  }
  shown = data;
  plotStats.drawMs = performance.now() - begin;
  if (wasPaused) plotStats.pausedDraws += 1;
}

function countFrame(now) {
  plotStats.frames += 1;
  fpsWindow.frames += 1;
  if (now - fpsWindow.start >= 1000) {
    plotStats.fps = (1000 * fpsWindow.frames) / (now - fpsWindow.start);
    fpsWindow = { start: now, frames: 0 };
    document.getElementById("plot-fps").textContent = paused ? "" : `${plotStats.fps.toFixed(0)} frames/s`;
  }
}

function draw(now) {
  requestAnimationFrame(draw);
  if (drawing || document.hidden) return;
  if (paused ? !relayoutNeeded : !dirty || now - lastFrame < FRAME_MS) return; // paused: no work
  dirty = false;
  drawing = true; // one draw at a time: a slow machine drops frames instead of queueing them
  lastFrame = now;
  render().then(() => countFrame(performance.now())).finally(() => { drawing = false; });
}

let frame = "base"; // hold-in-world plots the world frame: goal, tool and their error

function showHeading() {
  const heading = document.getElementById("plots-title");
  if (heading) heading.textContent = `${frame === "world" ? "World frame (hold)" : "Tracking"}, last ${windowS} s`;
  const state = document.getElementById("plot-state");
  if (state) {
    state.textContent = paused ? (zoom ? "paused, zoomed: double-click to restore" : "paused") : "";
    state.className = paused ? "plot-state paused" : "plot-state";
  }
  if (paused) document.getElementById("plot-fps").textContent = "";
  const button = document.getElementById("plot-pause");
  if (button) {
    button.textContent = paused ? "Resume" : "Pause";
    button.setAttribute("aria-pressed", String(paused));
  }
  Object.assign(plotStats, { paused, windowS, zoom: zoom ? [...zoom] : null });
}

function showFrame(next) {
  frame = next;
  for (const r of Object.values(series)) r.clear(); // never mix the two frames in one trace
  showHeading();
}

function onMessage(message) {
  if (paused) { // no work while paused: the samples are dropped, the plot stays as it was
    plotStats.dropped += 1;
    return;
  }
  const raw = JSON.parse(message.data);
  phiSample(raw); // the wrist's plot (phiplot.js; nothing without a wrist)
  if (raw.t < lastT - 1) for (const r of Object.values(series)) r.clear(); // server restarted
  else if (raw.t <= lastT) return;
  if (gapNext && lastT > -Infinity) { // the lines break where the pause was
    series.t.push((lastT + raw.t) / 2);
    for (const key of Object.keys(series)) if (key !== "t") series[key].push(NaN);
    plotStats.samples += 1;
  }
  gapNext = false;
  lastT = raw.t;
  if ((raw.world ? "world" : "base") !== frame) showFrame(raw.world ? "world" : "base");
  const m = raw.world || raw;
  series.t.push(raw.t);
  AXES.forEach((a, i) => {
    // rounded to 1 um so a resting axis does not show float noise
    const mm = (v) => (!v || v[i] === null ? NaN : Math.round(v[i] * 1e6) / 1e3);
    series[`goal_${a}`].push(mm(m.goal_m));
    series[`measured_${a}`].push(mm(m.measured_m));
    series[`error_${a}`].push(mm(m.error_m));
  });
  plotStats.samples += 1;
  dirty = true;
}

// ``askToken(reason, sent)``: how to get the token when the stream wants one (a promise);
// null: ask the operator here.
let askToken = null;

function connect(onState) {
  const sent = token();
  const ws = new WebSocket(telemetryUrl(HZ));
  ws.onopen = () => { plotStats.connected = true; onState(true); };
  ws.onmessage = onMessage;
  ws.onclose = async (event) => {
    plotStats.connected = false;
    onState(false);
    // 1008 = policy: the server wants a token; ask, then reconnect with it
    if (event.code === 1008) {
      const reason = "The telemetry stream requires a token.";
      await (askToken ? askToken(reason, sent) : promptToken(reason, sent));
    }
    setTimeout(() => connect(onState), 1000);
  };
}

export function setPaused(next) {
  if (next === paused) return;
  paused = next;
  pausedByZoom = false;
  if (paused) {
    relayoutNeeded = true; // one draw of what is shown, to update the heading
  } else {
    gapNext = true;
    zoom = null;
    relayoutNeeded = true;
    dirty = true;
  }
  showHeading();
}

function setWindow(seconds) {
  windowS = seconds;
  zoom = null;
  ranges = null;
  if (paused) shown = frameData(); // the samples kept before the pause, in the new window
  relayoutNeeded = true;
  dirty = true;
  showHeading();
}

// A drag on the plot (plotly's zoom box on the matched x axes): pause and show that range.
function onRelayout(event) {
  // the x axes are matched: any of them carries the range
  const key = Object.keys(event).find((k) => /^xaxis\d*\.range(\[0\])?$/.test(k));
  if (!key) return;
  const lo = key.endsWith("[0]") ? event[key] : event[key][0];
  const hi = key.endsWith("[0]") ? event[key.replace("[0]", "[1]")] : event[key][1];
  if (typeof lo !== "number" || typeof hi !== "number") return;
  const [a, b] = xRange();
  if (lo === a && hi === b) return; // our own redraw
  zoom = [lo, hi];
  if (!paused) {
    paused = true;
    pausedByZoom = true;
  }
  relayoutNeeded = true; // re-fit y to the samples inside the range
  showHeading();
}

function onDoubleClick() {
  zoom = null;
  relayoutNeeded = true;
  if (pausedByZoom) setPaused(false);
  else showHeading();
}

// The cursor: one vertical line per column of subplots at time t (three absolutely placed
// divs over the plot; moving them costs no plotly redraw).
let cursorT = null; // the time the cursor stands at [s], null when hidden

function placeCursor(t) {
  cursorT = t;
  const plot = document.getElementById("plot");
  const full = plot._fullLayout;
  if (!full || !full.xaxis) return;
  let lines = plot.querySelectorAll(".plot-cursor");
  if (lines.length !== 3) {
    lines.forEach((l) => l.remove());
    for (let i = 0; i < 3; i++) {
      const line = document.createElement("div");
      line.className = "plot-cursor";
      plot.append(line);
    }
    lines = plot.querySelectorAll(".plot-cursor");
  }
  lines.forEach((line, i) => {
    const xa = full[i === 0 ? "xaxis" : `xaxis${i + 1}`];
    const top = full[i === 0 ? "yaxis" : `yaxis${i + 1}`];
    const bottom = full[`yaxis${i + 4}`];
    const px = xa._offset + xa.l2p(t);
    const inside = px >= xa._offset && px <= xa._offset + xa._length;
    line.hidden = !inside;
    line.style.left = `${px}px`;
    line.style.top = `${top._offset}px`;
    line.style.height = `${bottom._offset + bottom._length - top._offset}px`;
  });
}

function hideCursor() {
  cursorT = null;
  document.querySelectorAll("#plot .plot-cursor").forEach((line) => { line.hidden = true; });
}

// The value of every series at the hovered time (the nearest drawn sample).
function onHover(event) {
  if (!shown || !shown.x.length) return;
  const t = event.xvals ? event.xvals[0] : event.points?.[0]?.x;
  if (typeof t !== "number") return;
  let lo = 0, hi = shown.x.length - 1;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (shown.x[mid] < t) lo = mid; else hi = mid;
  }
  const j = Math.abs(shown.x[lo] - t) <= Math.abs(shown.x[hi] - t) ? lo : hi;
  const value = (i) => (shown.y[i][j] === null ? "–" : shown.y[i][j].toFixed(2));
  const cells = AXES.map((a, ai) => {
    const parts = KINDS.map((k, ki) => {
      const i = ai * KINDS.length + ki;
      return `<span class="k-${k}">${k} <output data-series="${k}_${a}">${value(i)}</output></span>`;
    });
    return `<span class="axis"><b>${a}</b> ${parts.join(" ")}</span>`;
  });
  placeCursor(shown.x[j]);
  const out = document.getElementById("plot-readout");
  out.dataset.t = String(shown.x[j]);
  out.dataset.index = String(j);
  out.innerHTML = `<span>t − now <output data-series="t">${shown.x[j].toFixed(2)}</output> s</span>` +
    `${cells.join("")}<span class="muted">mm</span>`;
}

// The plots as shown, as a PNG file.
async function snapshot() {
  const plot = document.getElementById("plot");
  try {
    const url = await window.Plotly.toImage(plot, { format: "png", width: plot.clientWidth, height: plot.clientHeight });
    const link = document.createElement("a");
    const stamp = new Date().toISOString().replace(/[:.]/g, "-").slice(0, 19);
    link.href = url;
    link.download = `deltadash-plots-${stamp}.png`;
    document.body.append(link);
    link.click();
    link.remove();
  } catch (err) {
    document.getElementById("plot-state").textContent = `snapshot failed: ${err.message}`;
  }
}

// plotly's events exist once it has drawn: hooked right after the first full draw
let hooked = false;
function hookEvents() {
  const plot = document.getElementById("plot");
  if (hooked || !plot.on) return;
  hooked = true;
  plot.on("plotly_relayout", onRelayout);
  plot.on("plotly_doubleclick", onDoubleClick);
  plot.on("plotly_hover", onHover);
  plot.on("plotly_unhover", hideCursor);
}

function startControls() {
  document.getElementById("plot-pause").addEventListener("click", () => setPaused(!paused));
  document.getElementById("plot-snapshot").addEventListener("click", snapshot);
  const select = document.getElementById("plot-window");
  select.value = String(windowS);
  select.addEventListener("change", () => setWindow(Number(select.value)));
  showHeading();
}

// ``onState(online)``: the stream's state; ``ask``: see askToken.
export function startPlots(onState, ask = null) {
  askToken = ask;
  if (!window.Plotly) {
    document.getElementById("plot").textContent = "plotly.js did not load (/vendor/plotly.min.js).";
    return;
  }
  startControls();
  startPhiPlot(() => ({ windowS, paused }));
  connect(onState);
  requestAnimationFrame(draw);
}
