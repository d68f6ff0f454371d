// The XY path: the tool's goal and measured x, y [mm] over the tracking plots' window (or
// the replayed run), seen from above, equal scales. plots.js hands it the samples it draws
// (the same picks, so a point here is a point there) at most 10 times a second. Cheap like
// the others: a fixed square range kept while the path fits and fills a fair part of it,
// so most frames are a plotly animate without a redraw.

const MIN_SPAN_MM = 2; // a resting tool does not zoom into noise
const STYLE = {
  goal: { color: "#8a94a6", width: 2, dash: "dot" },
  measured: { color: "#2f7de1", width: 1.5 },
};

// Exposed for the browser test: frames drawn, full draws, the range in force.
export const xyStats = { frames: 0, fullDraws: 0, range: null };
window.deltadashXY = xyStats;

let started = false;
let range = null; // { x: [lo, hi], y: [lo, hi] } [mm], square

function needed(xy) {
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  for (const [xs, ys] of [xy.goal, xy.measured]) {
    for (let j = 0; j < xs.length; j++) {
      if (xs[j] === null || ys[j] === null) continue;
      x0 = Math.min(x0, xs[j]); x1 = Math.max(x1, xs[j]);
      y0 = Math.min(y0, ys[j]); y1 = Math.max(y1, ys[j]);
    }
  }
  return x0 > x1 ? null : { x: [x0, x1], y: [y0, y1] };
}

// Keep the square range while the path fits inside and fills a fair part of it.
function update(xy) {
  const need = needed(xy);
  if (need === null) return range === null;
  const span = Math.max(need.x[1] - need.x[0], need.y[1] - need.y[0], MIN_SPAN_MM);
  const fits = range && need.x[0] >= range.x[0] && need.x[1] <= range.x[1] &&
    need.y[0] >= range.y[0] && need.y[1] <= range.y[1] && range.x[1] - range.x[0] <= 4 * span;
  if (fits) return false;
  const half = 0.65 * span;
  const cx = (need.x[0] + need.x[1]) / 2, cy = (need.y[0] + need.y[1]) / 2;
  range = { x: [cx - half, cx + half], y: [cy - half, cy + half] };
  return true;
}

function layout() {
  const r = range || { x: [-1, 1], y: [-1, 1] };
  return {
    margin: { l: 48, r: 8, t: 8, b: 34 }, showlegend: false, hovermode: "closest",
    font: { family: "system-ui, sans-serif", size: 11 }, paper_bgcolor: "#fff", plot_bgcolor: "#fff",
    xaxis: { range: r.x, title: { text: "x [mm]", standoff: 2 }, gridcolor: "#eef0f3", zerolinecolor: "#c9ced6", fixedrange: true },
    yaxis: { range: r.y, title: { text: "y [mm]", standoff: 4 }, gridcolor: "#eef0f3", zerolinecolor: "#c9ced6",
      fixedrange: true, scaleanchor: "x", scaleratio: 1 },
  };
}

// Draw the path ``xy`` = { goal: [xs, ys], measured: [xs, ys] } [mm]; ``full`` forces a
// full redraw (what is shown is final: paused, replay, new window).
export async function drawXY(xy, full = false) {
  if (!started) return;
  // the latest measured point as a dot: a tool at rest is a line of no length
  const [mx, my] = xy.measured;
  let last = mx.length - 1;
  while (last >= 0 && (mx[last] === null || my[last] === null)) last -= 1;
  const traces = [
    { x: xy.goal[0], y: xy.goal[1] },
    { x: xy.measured[0], y: xy.measured[1] },
    { x: last >= 0 ? [mx[last]] : [], y: last >= 0 ? [my[last]] : [] },
  ];
  if (update(xy) || full || xyStats.fullDraws === 0) {
    await window.Plotly.react("plot-xy", [
      { ...traces[0], name: "goal", type: "scatter", mode: "lines", line: STYLE.goal,
        hovertemplate: "goal x %{x:.2f}, y %{y:.2f} mm<extra></extra>" },
      { ...traces[1], name: "measured", type: "scatter", mode: "lines", line: STYLE.measured,
        hovertemplate: "measured x %{x:.2f}, y %{y:.2f} mm<extra></extra>" },
      { ...traces[2], name: "latest", type: "scatter", mode: "markers", marker: { color: STYLE.measured.color, size: 7 },
        hovertemplate: "latest x %{x:.2f}, y %{y:.2f} mm<extra></extra>" },
    ], layout(), { displayModeBar: false, responsive: true });
    xyStats.fullDraws += 1;
  } else {
    await window.Plotly.animate("plot-xy", { data: traces, traces: [0, 1, 2] },
      { transition: { duration: 0 }, frame: { duration: 0, redraw: false }, mode: "immediate" });
  }
  xyStats.range = range ? { x: [...range.x], y: [...range.y] } : null;
  xyStats.frames += 1;
}

export function startXY() {
  if (!window.Plotly || !document.getElementById("plot-xy")) return;
  started = true;
}
