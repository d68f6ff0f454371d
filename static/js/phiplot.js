// The wrist's plot (only with a wrist): phi's goal and measured value [deg] over the
// tracking plots' time window, from the same telemetry messages (plots.js hands each one
// here). Cheap by design: fixed axes (x: time relative to now over the window, y: the
// wrist's limits), so each frame is a plotly animate without a redraw; paused with them.

import { Ring } from "./ring.js";
import { wrist } from "./wrist.js";

const CAPACITY = 50 * 300 + 100; // 5 min (the longest window) at the 50 Hz the plots ask for
const FRAME_MS = 100; // 10 frames/s: a wrist angle needs no more
const DEG = 180 / Math.PI;
const series = { t: new Ring(CAPACITY), goal: new Ring(CAPACITY), measured: new Ring(CAPACITY) };

// Exposed for the browser test: samples taken, frames drawn.
export const phiStats = { samples: 0, frames: 0 };
window.deltadashPhiPlot = phiStats;

let started = false;
let dirty = false;
let drawing = false;
let lastFrame = 0;
let lastT = -Infinity;
let view = () => ({ windowS: 10, paused: false }); // the tracking plots' window and pause

const value = (v) => (v === null || v === undefined || !Number.isFinite(v) ? NaN : Math.round(v * DEG * 100) / 100);

// One telemetry message (plots.js): its time, the wrist's goal and measured angle.
export function phiSample(raw) {
  if (!started || !raw.ee) return;
  if (raw.t < lastT - 1) for (const r of Object.values(series)) r.clear(); // server restarted
  else if (raw.t <= lastT) return;
  lastT = raw.t;
  series.t.push(raw.t);
  series.goal.push(value(raw.ee.goal_phi_rad));
  series.measured.push(value(raw.ee.phi_rad));
  phiStats.samples += 1;
  dirty = true;
}

function frameData(windowS) {
  const t = series.t.view();
  let first = t.length;
  while (first > 0 && t[first - 1] >= lastT - windowS - 0.1) first -= 1;
  const step = Math.max(1, Math.ceil((t.length - first) / 600));
  const pick = [];
  for (let i = first; i < t.length; i += step) pick.push(i);
  const pickOf = (ring) => { const v = ring.view(); return pick.map((i) => (Number.isNaN(v[i]) ? null : v[i])); };
  return { x: pick.map((i) => t[i] - lastT), goal: pickOf(series.goal), measured: pickOf(series.measured) };
}

function layout(windowS) {
  const pad = 5; // deg beyond the limits
  return {
    margin: { l: 52, r: 8, t: 4, b: 30 }, showlegend: true, hovermode: false,
    legend: { orientation: "h", x: 1, xanchor: "right", y: 1.0, yanchor: "bottom", bgcolor: "rgba(0,0,0,0)" },
    font: { family: "system-ui, sans-serif", size: 11 }, paper_bgcolor: "#fff", plot_bgcolor: "#fff",
    xaxis: { range: [-windowS, 0], fixedrange: true, gridcolor: "#eef0f3", zeroline: false,
      title: { text: "t − now [s]", standoff: 2 } },
    yaxis: { range: [wrist.minRad * DEG - pad, wrist.maxRad * DEG + pad], fixedrange: true,
      title: { text: "φ [°]", standoff: 4 }, gridcolor: "#eef0f3", zerolinecolor: "#c9ced6" },
  };
}

let shownWindowS = null;

async function render() {
  const { windowS } = view();
  const data = frameData(windowS);
  if (windowS !== shownWindowS) {
    shownWindowS = windowS;
    await window.Plotly.react("plot-phi", [
      { x: data.x, y: data.goal, name: "goal φ", type: "scatter", mode: "lines", line: { color: "#8a94a6", width: 2, dash: "dot" } },
      { x: data.x, y: data.measured, name: "measured φ", type: "scatter", mode: "lines", line: { color: "#2f7de1", width: 1.5 } },
    ], layout(windowS), { displayModeBar: false, responsive: true, staticPlot: true });
  } else {
    await window.Plotly.animate("plot-phi", { data: [{ x: data.x, y: data.goal }, { x: data.x, y: data.measured }], traces: [0, 1] },
      { transition: { duration: 0 }, frame: { duration: 0, redraw: false }, mode: "immediate" });
  }
  phiStats.frames += 1;
}

function draw(now) {
  requestAnimationFrame(draw);
  if (drawing || document.hidden || !dirty || view().paused || now - lastFrame < FRAME_MS) return;
  dirty = false;
  drawing = true;
  lastFrame = now;
  render().finally(() => { drawing = false; });
}

// Start the plot when a wrist is fitted; ``viewOf()`` gives the tracking plots' { windowS, paused }.
export function startPhiPlot(viewOf) {
  if (!wrist.enabled || !window.Plotly) return;
  view = viewOf;
  started = true;
  requestAnimationFrame(draw);
}
