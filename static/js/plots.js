// Live tracking plots from the telemetry WebSocket: per axis goal vs measured, and the error.
// plotly.js (served by the app from the plotly package) draws. Speed matters at >= 20
// frames/s: a full Plotly.react costs 45-150 ms on a loaded 2-core machine, its
// animate(redraw: false) path about 20 ms, so frames use animate with fixed axes (time
// relative to now, y ranges with hysteresis) and a full redraw only when a range must change.
// Ring buffers hold a fixed 10 s, so an hour-long session stays as fast as the first minute.

import { telemetryUrl, promptToken, token } from "./api.js";
import { Ring } from "./ring.js";

const HZ = 50;
const WINDOW_S = 10;
const CAPACITY = HZ * WINDOW_S + 50; // a little slack for rate jitter
const FRAME_MS = 33; // aim at 30 frames/s: headroom above the 20 the operator needs
const MIN_SPAN_MM = [2, 0.2]; // position, error: a resting signal does not zoom into noise
const AXES = ["x", "y", "z"];
const KINDS = ["goal", "measured", "error"];
const STYLE = {
  goal: { color: "#8a94a6", width: 2, dash: "dot" },
  measured: { color: "#2f7de1", width: 1.5 },
  error: { color: "#d9480f", width: 1.5 },
};

const series = { t: new Ring(CAPACITY) };
for (const a of AXES) for (const k of KINDS) series[`${k}_${a}`] = new Ring(CAPACITY);

// Exposed for the browser test and for anyone curious in the console.
export const plotStats = { samples: 0, frames: 0, fullDraws: 0, fps: 0, drawMs: 0, connected: false };
window.deltadashPlot = plotStats;

let dirty = false;
let drawing = false;
let lastFrame = 0;
let lastT = -Infinity;
let ranges = null; // [6][2] y ranges in force, null before the first full draw
let fpsWindow = { start: performance.now(), frames: 0 };

// Trace order: per axis i, goal and measured on subplot i + 1, error on subplot i + 4.
function traceKeys() {
  return AXES.flatMap((a, i) => KINDS.map((k) => ({ key: `${k}_${a}`, kind: k, plot: k === "error" ? i + 4 : i + 1 })));
}
const TRACES = traceKeys();

function frameData() {
  const t = series.t.view();
  const x = Array.from(t, (v) => v - lastT);
  return TRACES.map(({ key }) => ({ x, y: series[key].values() }));
}

function fullTraces(data) {
  return TRACES.map(({ kind, plot }, i) => ({
    ...data[i], type: "scatter", mode: "lines", hoverinfo: "skip", name: kind, line: STYLE[kind],
    xaxis: `x${plot}`, yaxis: `y${plot}`, showlegend: plot === 1 || (plot === 4 && kind === "error"),
  }));
}

function layout() {
  const base = {
    margin: { l: 52, r: 8, t: 8, b: 30 }, showlegend: true,
    grid: { rows: 2, columns: 3, pattern: "independent", roworder: "top to bottom" },
    legend: { orientation: "h", x: 1, xanchor: "right", y: 1.0, yanchor: "bottom", bgcolor: "rgba(0,0,0,0)" },
    font: { family: "system-ui, sans-serif", size: 11 }, paper_bgcolor: "#fff", plot_bgcolor: "#fff",
  };
  for (let n = 1; n <= 6; n++) {
    const suffix = n === 1 ? "" : n;
    base[`xaxis${suffix}`] = { range: [-WINDOW_S, 0], gridcolor: "#eef0f3", zeroline: false,
      title: n > 3 ? { text: "t − now [s]", standoff: 2 } : undefined };
    const label = n <= 3 ? `${AXES[n - 1]} [mm]` : `error ${AXES[n - 4]} [mm]`;
    base[`yaxis${suffix}`] = { range: ranges[n - 1], title: { text: label, standoff: 4 },
      gridcolor: "#eef0f3", zerolinecolor: "#c9ced6", tickformat: "~r" };
  }
  return base;
}

// The y range each subplot needs now, padded; null where it has no data.
function neededRanges(data) {
  const out = [];
  for (let n = 1; n <= 6; n++) {
    let lo = Infinity, hi = -Infinity;
    data.forEach((d, i) => {
      if (TRACES[i].plot !== n) return;
      for (const v of d.y) if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
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
  const data = frameData();
  const begin = performance.now();
  if (updateRanges(data)) {
    await window.Plotly.react("plot", fullTraces(data), layout(), { displayModeBar: false, responsive: true });
    plotStats.fullDraws += 1;
  } else {
    await window.Plotly.animate("plot", { data, traces: TRACES.map((_, i) => i) },
      { transition: { duration: 0 }, frame: { duration: 0, redraw: false }, mode: "immediate" });
  }
  plotStats.drawMs = performance.now() - begin;
}

function countFrame(now) {
  plotStats.frames += 1;
  fpsWindow.frames += 1;
  if (now - fpsWindow.start >= 1000) {
    plotStats.fps = (1000 * fpsWindow.frames) / (now - fpsWindow.start);
    fpsWindow = { start: now, frames: 0 };
    document.getElementById("plot-fps").textContent = `${plotStats.fps.toFixed(0)} frames/s`;
  }
}

function draw(now) {
  requestAnimationFrame(draw);
  if (!dirty || drawing || now - lastFrame < FRAME_MS || document.hidden) return;
  dirty = false;
  drawing = true; // one draw at a time: a slow machine drops frames instead of queueing them
  lastFrame = now;
  render().then(() => countFrame(performance.now())).finally(() => { drawing = false; });
}

let frame = "base"; // hold-in-world plots the world frame: goal, tool and their error

function showFrame(next) {
  frame = next;
  for (const r of Object.values(series)) r.clear(); // never mix the two frames in one trace
  const heading = document.getElementById("plots-h");
  if (heading && heading.firstChild) {
    heading.firstChild.textContent = next === "world" ? "World frame (hold), last 10 s " : "Tracking, last 10 s ";
  }
}

function onMessage(message) {
  const raw = JSON.parse(message.data);
  if (raw.t < lastT - 1) for (const r of Object.values(series)) r.clear(); // server restarted
  else if (raw.t <= lastT) return;
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

function connect(onState) {
  const sent = token();
  const ws = new WebSocket(telemetryUrl(HZ));
  ws.onopen = () => { plotStats.connected = true; onState(true); };
  ws.onmessage = onMessage;
  ws.onclose = async (event) => {
    plotStats.connected = false;
    onState(false);
    // 1008 = policy: the server wants a token; ask, then reconnect with it
    if (event.code === 1008) await promptToken("The telemetry stream requires a token.", sent);
    setTimeout(() => connect(onState), 1000);
  };
}

export function startPlots(onState) {
  if (!window.Plotly) {
    document.getElementById("plot").textContent = "plotly.js did not load (/vendor/plotly.min.js).";
    return;
  }
  connect(onState);
  requestAnimationFrame(draw);
}
