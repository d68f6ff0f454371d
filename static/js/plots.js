// Live tracking plots from the telemetry WebSocket: per axis goal vs measured, and the error.
// plotly.js (served by the app from the plotly package) draws. Speed matters at >= 20
// frames/s: a full Plotly.react costs 45-150 ms on a loaded 2-core machine, its
// animate(redraw: false) path about 20 ms, so frames use animate with fixed axes (time
// relative to now, y ranges with hysteresis) and a full redraw only when a range must change.
// Ring buffers hold a fixed 5 min (the longest window), so an hour-long session stays as
// fast as the first minute; windows over 10 s draw every n-th sample (at most ~600 per trace).
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
// - The time window: 5 s to 5 min. The signals: position (goal, measured, error per axis),
//   joints (commanded, measured, error per joint), servos (current and PWM per leg servo),
//   the drone's pose in a hold (position and attitude), the tip force (the contact force
//   estimate per axis and its 1-sigma, telemetry "contact"). y zoom: fit, or 2-10 times closer.
// - Replay: a recorded run (GET /api/runs/{id}/series) in the same plots, against run time;
//   live samples are dropped meanwhile, "Live" goes back.
// - The XY path (plotsxy.js): the tool's path seen from above over the window.

import { get, telemetryUrl, promptToken, token } from "./api.js";
import { phiSample, startPhiPlot } from "./phiplot.js";
import { drawXY, startXY } from "./plotsxy.js";
import { Ring } from "./ring.js";

const HZ = 50;
const WINDOWS_S = [5, 10, 30, 60, 120, 300];
const CAPACITY = HZ * WINDOWS_S[WINDOWS_S.length - 1] + 100; // slack for rate jitter
const MAX_POINTS = 600; // per trace and frame: longer windows draw every n-th sample
const REPLAY_POINTS = 15000; // a replay asks for at most this many ticks (5 min at 50 Hz)
const FRAME_MS = 33; // aim at 30 frames/s: headroom above the 20 the operator needs
const Y_ZOOMS = [1, 2, 5, 10];
const DEG = 180 / Math.PI;
const KINDS = ["goal", "measured", "error"]; // the three trace slots per column (style)
const STYLE = {
  goal: { color: "#8a94a6", width: 2, dash: "dot" },
  measured: { color: "#2f7de1", width: 1.5 },
  error: { color: "#d9480f", width: 1.5 },
};
const CONFIG = { displayModeBar: false, responsive: true, doubleClick: false };

// The signal sets: three columns, each with two traces on top and one underneath. ``names``
// are the three slots' names (null: the slot is not used), as the readout and the legend
// say them; ``minSpan``: the smallest y span (top, bottom) so a resting signal does not
// zoom into noise.
const SETS = {
  position: {
    label: "position", columns: ["x", "y", "z"], names: ["goal", "measured", "error"],
    top: (c) => `${c} [mm]`, bottom: (c) => `error ${c} [mm]`, unit: "mm", minSpan: [2, 0.2],
  },
  joints: {
    label: "joints", columns: ["q1", "q2", "q3"], names: ["commanded", "measured", "error"],
    top: (c) => `${c} [°]`, bottom: (c) => `error ${c} [°]`, unit: "°", minSpan: [1, 0.1],
  },
  servos: {
    label: "servo current and PWM", columns: ["leg 1", "leg 2", "leg 3"], names: [null, "current", "pwm"],
    top: (c) => `${c} current [A]`, bottom: (c) => `${c} PWM [%]`, unit: "A, %", minSpan: [0.1, 2],
  },
  drone: {
    label: "drone pose", columns: ["x", "y", "z"], names: [null, "position", "attitude"],
    top: (c) => `drone ${c} [mm]`, bottom: (c, i) => `drone ${["roll", "pitch", "yaw"][i]} [°]`,
    unit: "mm, °", minSpan: [2, 0.5],
  },
  force: {
    label: "tip force", columns: ["x", "y", "z"], names: [null, "force", "1σ"],
    top: (c) => `tip force ${c} [N]`, bottom: (c) => `1σ ${c} [N]`, unit: "N", minSpan: [1, 0.1],
  },
};
let set = "position";

// Traces per column i: slot 0 and 1 on subplot i + 1, slot 2 on subplot i + 4.
const TRACES = [0, 1, 2].flatMap((i) => KINDS.map((kind, slot) => ({ column: i, slot, kind, plot: slot === 2 ? i + 4 : i + 1 })));

const series = { t: new Ring(CAPACITY) };
for (const [name, spec] of Object.entries(SETS)) {
  for (const { column, slot } of TRACES) if (spec.names[slot]) series[`${name}_${slot}_${column}`] = new Ring(CAPACITY);
}

// Exposed for the browser test and for anyone curious in the console.
export const plotStats = {
  samples: 0, frames: 0, fullDraws: 0, fps: 0, drawMs: 0, connected: false,
  dropped: 0, paused: false, windowS: 10, zoom: null, signals: set, yZoom: 1, yRanges: null,
  replay: null, // the run replayed: {run_id, samples, stride, points}, null when live
  pausedDraws: 0, // draws begun while paused: after a pause, the one that fixes what is shown
};
window.deltadashPlot = plotStats;

let dirty = false;
let drawing = false;
let lastFrame = 0;
let lastT = -Infinity;
let ranges = null; // [6][2] y ranges in force (before the y zoom), null before the first full draw
let fpsWindow = { start: performance.now(), frames: 0 };
let windowS = 10;
let yZoom = 1;
let paused = false;
let pausedByZoom = false;
let gapNext = false; // the first sample after a pause starts a new line
let zoom = null; // [t0, t1] the selected time range (s, relative to the last sample), or null
let relayoutNeeded = false; // a full redraw of the shown data (window, zoom, pause changed)
let shown = null; // { x, y: [9][] } the data on screen (the cursor reads it)
let replay = null; // the run replayed: { run_id, kind, t0, t1, samples, stride }, null live
let lastXY = 0;

function stride() {
  return Math.max(1, Math.ceil((windowS * HZ) / MAX_POINTS));
}

// The index of the first sample at or after time ``t`` in the ascending ``times``.
function firstAtOrAfter(times, t) {
  let lo = 0, hi = times.length;
  while (lo < hi) {
    const mid = (lo + hi) >> 1;
    if (times[mid] < t) lo = mid + 1; else hi = mid;
  }
  return lo;
}

// The samples of the window, every stride-th one counted from the first ever received (so
// a decimated line does not shimmer from frame to frame); null for unknown values. In a
// replay: the whole run (already decimated by the server), against run time.
function frameData() {
  const t = series.t.view();
  const pick = [];
  if (replay) {
    const step = Math.max(1, Math.ceil(t.length / REPLAY_POINTS));
    for (let i = 0; i < t.length; i += step) pick.push(i);
  } else {
    let first = firstAtOrAfter(t, lastT - windowS - 0.1);
    const step = stride();
    const offset = plotStats.samples - t.length; // absolute index of t[0]
    first += (step - ((offset + first) % step)) % step;
    for (let i = first; i < t.length; i += step) pick.push(i);
  }
  const x = pick.map((i) => (replay ? t[i] : t[i] - lastT));
  const y = TRACES.map(({ column, slot }) => {
    const ring = series[`${set}_${slot}_${column}`];
    if (!ring) return pick.map(() => null);
    const v = ring.view();
    return pick.map((i) => (Number.isNaN(v[i]) ? null : v[i]));
  });
  // the XY path always shows the position: goal and measured x, y
  const of = (slot, column) => { const v = series[`position_${slot}_${column}`].view(); return pick.map((i) => (Number.isNaN(v[i]) ? null : v[i])); };
  const xy = { goal: [of(0, 0), of(0, 1)], measured: [of(1, 0), of(1, 1)] };
  return { x, y, xy };
}

function asTraces(data) {
  return TRACES.map((_, i) => ({ x: data.x, y: data.y[i] }));
}

function fullTraces(data) {
  const names = SETS[set].names;
  return TRACES.map(({ kind, slot, plot }, i) => ({
    x: data.x, y: data.y[i], type: "scatter", mode: "lines", hoverinfo: "none", name: names[slot] || kind, line: STYLE[kind],
    xaxis: `x${plot}`, yaxis: `y${plot}`, visible: names[slot] ? true : false,
    showlegend: Boolean(names[slot]) && (plot === 1 || (plot === 4 && slot === 2)),
  }));
}

function xRange() {
  if (zoom) return [...zoom];
  return replay ? [replay.t0, replay.t1] : [-windowS, 0];
}

// ``range`` seen ``factor`` times closer about its middle (the y zoom).
function zoomed(range) {
  const mid = (range[0] + range[1]) / 2, half = (range[1] - range[0]) / 2 / yZoom;
  return [mid - half, mid + half];
}

function layout() {
  const spec = SETS[set];
  const base = {
    margin: { l: 52, r: 8, t: 8, b: 30 }, showlegend: true, dragmode: "zoom", hovermode: "x",
    grid: { rows: 2, columns: 3, pattern: "independent", roworder: "top to bottom" },
    legend: { orientation: "h", x: 1, xanchor: "right", y: 1.0, yanchor: "bottom", bgcolor: "rgba(0,0,0,0)" },
    font: { family: "system-ui, sans-serif", size: 11 }, paper_bgcolor: "#fff", plot_bgcolor: "#fff",
  };
  const shownRanges = ranges.map(zoomed);
  plotStats.yRanges = shownRanges.map((r) => [...r]);
  for (let n = 1; n <= 6; n++) {
    const suffix = n === 1 ? "" : n;
    base[`xaxis${suffix}`] = { range: xRange(), gridcolor: "#eef0f3", zeroline: false,
      matches: n === 1 ? undefined : "x",
      title: n > 3 ? { text: replay ? "run time [s]" : "t − now [s]", standoff: 2 } : undefined };
    const column = spec.columns[(n - 1) % 3];
    const label = n <= 3 ? spec.top(column, n - 1) : spec.bottom(column, n - 4);
    base[`yaxis${suffix}`] = { range: shownRanges[n - 1], title: { text: label, standoff: 4 }, fixedrange: true,
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
    const minSpan = SETS[set].minSpan[i < 3 ? 0 : 1];
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

let epoch = 0; // bumped when what is shown is replaced (a replay, live again): a draw begun
// before that must not put its data back as the shown one

async function render() {
  const wasPaused = paused;
  const began = epoch;
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
  if (began !== epoch) { // replaced meanwhile: draw the new data next
    relayoutNeeded = true;
    return;
  }
  shown = data;
  plotStats.drawMs = performance.now() - begin;
  if (wasPaused) plotStats.pausedDraws += 1;
  // the XY path at most 10 times a second, and whenever what is shown is final
  const now = performance.now();
  if (full || wasPaused || now - lastXY > 100) {
    lastXY = now;
    await drawXY(data.xy, full || wasPaused);
  }
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
const AXES_XYZ = ["x", "y", "z"];

function windowText(seconds) {
  return seconds >= 60 ? `${seconds / 60} min` : `${seconds} s`;
}

function showHeading() {
  const heading = document.getElementById("plots-title");
  const what = set === "position" ? (frame === "world" ? "World frame (hold)" : "Tracking") : SETS[set].label[0].toUpperCase() + SETS[set].label.slice(1);
  if (heading) {
    heading.textContent = replay
      ? `${what}, replay of run ${replay.run_id} (${replay.kind}, ${(replay.t1 - replay.t0).toFixed(1)} s)`
      : `${what}, last ${windowText(windowS)}`;
  }
  const state = document.getElementById("plot-state");
  if (state) {
    let text = paused ? (zoom ? "paused, zoomed: double-click to restore" : "paused") : "";
    if (replay) text = zoom ? "replay, zoomed: double-click to restore" : "replay: the recorded run, not live";
    if (replay && (set === "servos" || set === "drone")) text += `; the run's log has no ${SETS[set].label}`;
    state.textContent = text;
    state.className = paused ? "plot-state paused" : "plot-state";
  }
  if (paused) document.getElementById("plot-fps").textContent = "";
  const button = document.getElementById("plot-pause");
  if (button) {
    button.textContent = paused && !replay ? "Resume" : "Pause";
    button.setAttribute("aria-pressed", String(paused));
    button.hidden = Boolean(replay);
  }
  const live = document.getElementById("plot-live");
  if (live) live.hidden = !replay;
  const phi = document.getElementById("plot-phi"); // the wrist's live plot: not during a replay
  if (phi && replay && !phi.hidden) { phi.hidden = true; phi.dataset.replayHid = "1"; }
  if (phi && !replay && phi.dataset.replayHid) { phi.hidden = false; delete phi.dataset.replayHid; }
  const select = document.getElementById("plot-window");
  if (select) select.disabled = Boolean(replay);
  Object.assign(plotStats, {
    paused, windowS, zoom: zoom ? [...zoom] : null, signals: set, yZoom,
    replay: replay ? { run_id: replay.run_id, samples: replay.samples, stride: replay.stride, points: replay.points } : null,
  });
}

function showFrame(next) {
  frame = next;
  for (const r of Object.values(series)) r.clear(); // never mix the two frames in one trace
  showHeading();
}

// One telemetry message's values per set and slot, in display units (mm, deg, A, %):
// rounded so a resting signal does not show float noise.
const round = (v, scale, digits) => (v === null || v === undefined || !Number.isFinite(v) ? NaN : Math.round(v * scale * digits) / digits);

// roll, pitch, yaw [deg] of a quaternion (w, x, y, z), z-y-x order
export function attitude(w, x, y, z) {
  const roll = Math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y));
  const pitch = Math.asin(Math.max(-1, Math.min(1, 2 * (w * y - z * x))));
  const yaw = Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
  return [roll, pitch, yaw];
}

function pushSample(values) {
  for (const [key, value] of Object.entries(values)) series[key].push(value);
}

function liveValues(raw) {
  const m = raw.world || raw;
  const out = {};
  const joint = (v, i) => (v ? v[i] : null);
  const pose = raw.world && raw.world.drone_pose;
  const turn = pose && pose.length === 7 ? attitude(pose[3], pose[4], pose[5], pose[6]) : null;
  const force = raw.contact || {}; // the force the tip applies, base frame [N] (null: unknown)
  for (let i = 0; i < 3; i++) {
    const mm = (v) => round(v ? v[i] : null, 1000, 1000); // [m] -> mm, 1 um steps
    out[`position_0_${i}`] = mm(m.goal_m);
    out[`position_1_${i}`] = mm(m.measured_m);
    out[`position_2_${i}`] = mm(m.error_m);
    const commanded = joint(raw.commanded_joints_rad, i), measured = joint(raw.measured_joints_rad, i);
    out[`joints_0_${i}`] = round(commanded, DEG, 1000);
    out[`joints_1_${i}`] = round(measured, DEG, 1000);
    out[`joints_2_${i}`] = commanded === null || measured === null ? NaN : round(commanded - measured, DEG, 1000);
    out[`servos_1_${i}`] = round(joint(raw.current_a, i), 1, 1000);
    out[`servos_2_${i}`] = round(joint(raw.pwm, i), 100, 100);
    out[`drone_1_${i}`] = round(pose ? pose[i] : null, 1000, 1000);
    out[`drone_2_${i}`] = round(turn ? turn[i] : null, DEG, 1000);
    out[`force_1_${i}`] = round(joint(force.force_n, i), 1, 1000);
    out[`force_2_${i}`] = round(joint(force.std_n, i), 1, 1000);
  }
  return out;
}

function onMessage(message) {
  if (paused) { // no work while paused (or replaying): the samples are dropped, the plot stays
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
  series.t.push(raw.t);
  pushSample(liveValues(raw));
  plotStats.samples += 1;
  dirty = true;
}

// A recorded run in the plots (GET /api/runs/{id}/series): the log's values, in the same
// units as live; what the log does not have (servo current and PWM, the drone's pose, the
// tip force's 1σ) is
// left empty. Live samples are dropped until liveAgain().
export async function replayRun(runId) {
  const state = document.getElementById("plot-state");
  let body;
  try {
    body = await get(`/api/runs/${encodeURIComponent(runId)}/series?max_points=${REPLAY_POINTS}`);
  } catch (err) {
    if (state) state.textContent = `run ${runId} cannot be replayed: ${err.message}`;
    return false;
  }
  if (!body.t_s.length) {
    if (state) state.textContent = `run ${runId} has no recorded ticks to replay`;
    return false;
  }
  paused = true; // live samples are dropped meanwhile
  pausedByZoom = false;
  zoom = null;
  ranges = null;
  for (const r of Object.values(series)) r.clear();
  const sig = body.signals;
  const world = "world_goal_x_m" in sig;
  const at = (name, j) => (sig[name] ? sig[name][j] : null);
  const n = Math.min(body.t_s.length, CAPACITY);
  const from = body.t_s.length - n; // a run longer than the rings: its last part
  for (let j = from; j < body.t_s.length; j++) {
    series.t.push(body.t_s[j]);
    const values = {};
    AXES_XYZ.forEach((a, i) => {
      const p = world ? "world_" : "";
      values[`position_0_${i}`] = round(at(`${p}goal_${a}_m`, j), 1000, 1000);
      values[`position_1_${i}`] = round(at(`${p}measured_${a}_m`, j), 1000, 1000);
      values[`position_2_${i}`] = round(at(`${p}error_${a}_m`, j), 1000, 1000);
      const commanded = at(`commanded_q${i + 1}_rad`, j), measured = at(`measured_q${i + 1}_rad`, j);
      values[`joints_0_${i}`] = round(commanded, DEG, 1000);
      values[`joints_1_${i}`] = round(measured, DEG, 1000);
      values[`joints_2_${i}`] = commanded === null || measured === null ? NaN : round(commanded - measured, DEG, 1000);
      for (const key of [`servos_1_${i}`, `servos_2_${i}`, `drone_1_${i}`, `drone_2_${i}`]) values[key] = NaN;
      values[`force_1_${i}`] = round(at(`contact_force_${a}_n`, j), 1, 1000); // the log has no 1σ
      values[`force_2_${i}`] = NaN;
    });
    pushSample(values);
  }
  frame = world ? "world" : "base";
  const t0 = body.t_s[from], t1 = body.t_s[body.t_s.length - 1];
  replay = { run_id: body.run_id, kind: body.kind, t0, t1: t1 > t0 ? t1 : t0 + 1, samples: body.samples, stride: body.stride, points: n };
  epoch += 1;
  shown = frameData(); // what a paused plot draws: the run
  relayoutNeeded = true;
  showHeading();
  return true;
}

// Back to the live stream after a replay: the rings start empty.
export function liveAgain() {
  if (!replay) return;
  replay = null;
  for (const r of Object.values(series)) r.clear();
  epoch += 1;
  shown = null;
  lastT = -Infinity;
  ranges = null;
  zoom = null;
  frame = "base";
  paused = false;
  pausedByZoom = false;
  relayoutNeeded = true;
  dirty = true;
  showHeading();
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
  if (next === paused || replay) return;
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

function setSignals(name) {
  if (!SETS[name]) return;
  set = name;
  hideCursor();
  const readout = document.getElementById("plot-readout");
  readout.textContent = "hover a plot for the values at that time";
  delete readout.dataset.t;
  delete readout.dataset.index;
  ranges = null; // other units: fit afresh
  epoch += 1;
  if (paused) shown = frameData(); // what was kept, in the new signals
  relayoutNeeded = true;
  dirty = true;
  showHeading();
}

function setYZoom(factor) {
  yZoom = Y_ZOOMS.includes(factor) ? factor : 1;
  relayoutNeeded = true;
  dirty = true;
  showHeading();
}

function setWindow(seconds) {
  if (replay) return;
  windowS = seconds;
  zoom = null;
  ranges = null;
  epoch += 1;
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
  const spec = SETS[set];
  const cells = spec.columns.map((c, ci) => {
    const parts = KINDS.flatMap((k, slot) => {
      const name = spec.names[slot];
      if (!name) return [];
      const i = ci * KINDS.length + slot;
      return [`<span class="k-${k}">${name} <output data-series="${name}_${c}">${value(i)}</output></span>`];
    });
    return `<span class="axis"><b>${c}</b> ${parts.join(" ")}</span>`;
  });
  placeCursor(shown.x[j]);
  const out = document.getElementById("plot-readout");
  out.dataset.t = String(shown.x[j]);
  out.dataset.index = String(j);
  const when = replay ? "run time" : "t − now";
  out.innerHTML = `<span>${when} <output data-series="t">${shown.x[j].toFixed(2)}</output> s</span>` +
    `${cells.join("")}<span class="muted">${spec.unit}</span>`;
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
  document.getElementById("plot-live").addEventListener("click", liveAgain);
  const select = document.getElementById("plot-window");
  select.value = String(windowS);
  select.addEventListener("change", () => setWindow(Number(select.value)));
  const signals = document.getElementById("plot-signals");
  signals.value = set;
  signals.addEventListener("change", () => setSignals(signals.value));
  const yzoom = document.getElementById("plot-yzoom");
  yzoom.value = String(yZoom);
  yzoom.addEventListener("change", () => setYZoom(Number(yzoom.value)));
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
  startXY();
  startPhiPlot(() => ({ windowS, paused }));
  connect(onState);
  requestAnimationFrame(draw);
}
