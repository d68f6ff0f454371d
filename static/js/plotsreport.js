// The interactive report (report.html): a run's goal, measured position and error per axis
// drawn by plotly from its recorded signals (GET /api/runs/{id}/series), beside the report's
// PNG in the page's lightbox. plotly's own tools: drag to zoom (x and y), hover for the
// values under the pointer, double-click to restore, the camera icon for a PNG.
//
// The page loads it in a frame from the other loopback name (report.js; isolation.js): one
// full draw of thousands of points must not hold up the page's e-stop key. Messages:
//   frame -> page: {type: "ready"}, {type: "drawn", run_id, points},
//                  {type: "estop", press, event_unix_ms, sent_unix_ms, source}
//   page -> frame: {type: "token", token} (the page's token, or null: none needed)
// Opened on its own (report.html?run=ID) it works too.

import { get, setToken } from "./api.js";
import { isEstopKey, newPressId, postEstop } from "./estopkey.js";

const MESSAGE_TYPE = "deltadash-report";
const MAX_POINTS = 5000; // per signal: plotly's hover and zoom stay quick
const AXES = ["x", "y", "z"];
const STYLE = {
  goal: { color: "#8a94a6", width: 2, dash: "dot" },
  measured: { color: "#2f7de1", width: 1.5 },
  error: { color: "#d9480f", width: 1.5 },
};
const params = new URLSearchParams(location.search);
const runId = params.get("run");
const parentOrigin = params.get("parent");
const framed = window.parent !== window;

// Exposed for the browser test: the run drawn, its points per trace, an error.
export const reportStats = { runId, drawn: false, points: 0, error: null };
window.deltadashReport = reportStats;

function tell(body) {
  if (framed && parentOrigin) window.parent.postMessage({ kind: MESSAGE_TYPE, ...body }, parentOrigin);
}

function say(text) {
  document.getElementById("ir-state").textContent = text;
}

const mm = (v) => (v === null || v === undefined ? null : Math.round(v * 1e6) / 1e3);
const number = (v) => (v === null || v === undefined || !Number.isFinite(v) ? "–" : `${(v * 1e3).toFixed(2)} mm`);

function traces(body, world) {
  const s = body.signals;
  const prefix = world ? "world_" : "";
  const out = [];
  AXES.forEach((a, i) => {
    const column = (name) => (s[name] || []).map(mm);
    const hover = (what) => `${what} ${a} %{y:.3f} mm at %{x:.2f} s<extra></extra>`;
    out.push({ x: body.t_s, y: column(`${prefix}goal_${a}_m`), name: "goal", line: STYLE.goal,
      xaxis: `x${i + 1}`, yaxis: `y${i + 1}`, showlegend: i === 0, hovertemplate: hover("goal") });
    out.push({ x: body.t_s, y: column(`${prefix}measured_${a}_m`), name: "measured", line: STYLE.measured,
      xaxis: `x${i + 1}`, yaxis: `y${i + 1}`, showlegend: i === 0, hovertemplate: hover("measured") });
    out.push({ x: body.t_s, y: column(`${prefix}error_${a}_m`), name: "error", line: STYLE.error,
      xaxis: `x${i + 4}`, yaxis: `y${i + 4}`, showlegend: i === 0, hovertemplate: hover("error") });
  });
  return out.map((t) => ({ ...t, type: "scatter", mode: "lines" }));
}

function layout(world) {
  const base = {
    margin: { l: 56, r: 10, t: 10, b: 36 }, hovermode: "x", dragmode: "zoom",
    grid: { rows: 2, columns: 3, pattern: "independent", roworder: "top to bottom" },
    legend: { orientation: "h", x: 1, xanchor: "right", y: 1.0, yanchor: "bottom" },
    font: { family: "system-ui, sans-serif", size: 11 }, paper_bgcolor: "#fff", plot_bgcolor: "#fff",
  };
  for (let n = 1; n <= 6; n++) {
    const suffix = n === 1 ? "" : n;
    const a = AXES[(n - 1) % 3];
    base[`xaxis${suffix}`] = { matches: n === 1 ? undefined : "x", gridcolor: "#eef0f3", zeroline: false,
      title: n > 3 ? { text: "run time [s]", standoff: 2 } : undefined };
    base[`yaxis${suffix}`] = { gridcolor: "#eef0f3", zerolinecolor: "#c9ced6", tickformat: "~r",
      title: { text: n <= 3 ? `${world ? "world " : ""}${a} [mm]` : `error ${a} [mm]`, standoff: 4 } };
  }
  return base;
}

function summary(run, world) {
  const stats = (run.stats || {})[world ? "world" : "tracking"] || {};
  const parts = AXES.map((a) => `${a}: RMSE ${number((stats[a] || {}).rmse_m)}, max |e| ${number((stats[a] || {}).max_abs_m)}`);
  return `${run.description || run.kind}. ${parts.join("; ")}.`;
}

async function show() {
  if (!runId) {
    say("no run given (report.html?run=ID)");
    return;
  }
  document.getElementById("ir-title").textContent = `Run ${runId}: interactive report`;
  let run, body;
  try {
    const id = encodeURIComponent(runId);
    [run, body] = await Promise.all([get(`/api/runs/${id}`), get(`/api/runs/${id}/series?max_points=${MAX_POINTS}`)]);
  } catch (err) {
    reportStats.error = err.message;
    say(`the run's recorded signals could not be read: ${err.message}`);
    return;
  }
  const world = "world_goal_x_m" in body.signals;
  document.getElementById("ir-title").textContent = `Run ${runId}: ${run.kind}, ${run.state}`;
  document.getElementById("ir-summary").textContent = summary(run, world);
  const every = body.stride > 1 ? `every ${body.stride}th of ${body.samples} ticks` : `all ${body.samples} ticks`;
  say(`${every} of the whole run (the PNG shows its scored part); drag to zoom, hover for values, double-click to restore`);
  await window.Plotly.react("ir-plot", traces(body, world), layout(world),
    { responsive: true, displaylogo: false, modeBarButtonsToRemove: ["lasso2d", "select2d"] });
  Object.assign(reportStats, { drawn: true, points: body.t_s.length, stride: body.stride, world });
  tell({ type: "drawn", run_id: runId, points: body.t_s.length });
}

// Space / Esc while this frame has the focus: stop first, from here, then tell the page.
function onKey(event) {
  if (!isEstopKey(event)) return;
  event.preventDefault();
  event.stopImmediatePropagation();
  if (event.repeat) return;
  const press = newPressId();
  postEstop(press).catch(() => {});
  tell({
    type: "estop", press, source: event.type,
    event_unix_ms: performance.timeOrigin + event.timeStamp, sent_unix_ms: Date.now(),
  });
}

function start() {
  if (!window.Plotly) {
    say("plotly.js did not load (/vendor/plotly.min.js).");
    return;
  }
  window.addEventListener("keydown", onKey, { capture: true });
  if (!framed) {
    show();
    return;
  }
  let shown = false;
  window.addEventListener("message", (event) => {
    if (event.source !== window.parent || event.origin !== parentOrigin) return;
    const data = event.data || {};
    if (data.kind !== MESSAGE_TYPE || data.type !== "token" || shown) return;
    if (data.token) setToken(data.token);
    shown = true;
    show();
  });
  tell({ type: "ready" });
}

if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
else start();
