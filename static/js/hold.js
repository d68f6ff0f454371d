// Hold in world (docs/dashboard.md "Hold in world"): the drone's pose source chosen and
// watched live (GET /api/mav/pose, polled while the panel is on screen), the simulated drone started and stopped
// (POST /api/mav/simulated), a hold started at a world goal typed in mm (POST
// /api/tests/hold, a run on the pose input) and stopped (POST /api/runs/{id}/abort), a
// world-frame tracking plot while it holds (the telemetry stream's ``world``, drawn on a
// canvas 2D a few times a second: light, no plotly, the e-stop's renderer stays free) and
// the run's verdict after (GET /api/runs/{id}). Every check of typed input happens here,
// before anything is sent; the server checks again.

import { get, postControl, telemetryUrl, mm, fixed } from "./api.js";
import { operatorText, parseDecimal, setText } from "./ui.js";
import { wrist } from "./wrist.js";

const POSE_POLL_MS = 500;
const STREAM_HZ = 25;
const WINDOW_S = 30; // the plot's window
const DRAW_MS = 200;
const GAP_S = 0.25; // samples further apart than this are not joined in the plot
const REACH_M = 1.0; // /api/workspace/nearest's coordinates: |value| <= 1 m
const STATES = { ok: "fresh", stale: "STALE", lost: "LOST", none: "none yet" };
const SOURCES = {
  http: "HTTP (POST)", websocket: "WebSocket", udp: "UDP (motion capture)",
  mavlink: "MAVLink (autopilot)", simulated: "simulated drone",
};
const COLOURS = { goal: "#868e96", tool: "#1c7ed6", grid: "#e9ecef", axis: "#495057" };

const el = (id) => document.getElementById(id);
// what the page knows: the last pose status, the run it started, the samples of the plot
const hold = { pose: null, runId: null, samples: [], socket: null, drawn: 0 };
let drawTimer = null;

// ---- frames: quaternion (w, x, y, z) rotations, the tool in the world and back ----
function rotate(q, v) {
  const [w, x, y, z] = q;
  const t = [2 * (y * v[2] - z * v[1]), 2 * (z * v[0] - x * v[2]), 2 * (x * v[1] - y * v[0])];
  return [
    v[0] + w * t[0] + (y * t[2] - z * t[1]),
    v[1] + w * t[1] + (z * t[0] - x * t[2]),
    v[2] + w * t[2] + (x * t[1] - y * t[0]),
  ];
}
const conj = (q) => [q[0], -q[1], -q[2], -q[3]];
const add = (a, b) => a.map((v, k) => v + b[k]);
const sub = (a, b) => a.map((v, k) => v - b[k]);

// The base in the world: the drone's pose, then the mount (the base in the drone body).
function baseInWorld(pose) {
  return {
    apply: (p) => add(rotate(pose.quaternion, add(rotate(pose.mount_quaternion, p), pose.mount_position_m)), pose.position_m),
    inverse: (p) => rotate(conj(pose.mount_quaternion), sub(rotate(conj(pose.quaternion), sub(p, pose.position_m)), pose.mount_position_m)),
  };
}

// Roll, pitch, yaw [deg] of R = Rz(yaw) Ry(pitch) Rx(roll) from (w, x, y, z).
export function rollPitchYaw(q) {
  const [w, x, y, z] = q;
  const roll = Math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y));
  const pitch = Math.asin(Math.max(-1, Math.min(1, 2 * (w * y - z * x))));
  const yaw = Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
  return [roll, pitch, yaw].map((a) => a * 180 / Math.PI);
}

const live = (p) => p && p.position_m && p.quaternion && (p.state === "ok" || p.state === "stale");
const triple = (v, digits = 1) => (v ? v.map((c) => mm(c, digits)).join(", ") : "–");

function say(text, bad = false) {
  const m = el("hold-message");
  m.textContent = text;
  m.className = `hold-message${bad ? " bad" : ""}`;
}

function source() {
  return document.querySelector('input[name="hold-source"]:checked').value;
}

// ---- the live pose ----
function renderPose() {
  const p = hold.pose;
  if (!p) return;
  const state = el("hold-state");
  state.textContent = STATES[p.state] || p.state;
  state.className = p.state === "ok" ? "ok" : p.state === "none" ? "" : "bad";
  state.dataset.state = p.state;
  setText("hold-src", p.source ? SOURCES[p.source] || p.source : "–");
  setText("hold-rate", p.state === "none" ? "–" : `${fixed(p.rate_hz, 0)} Hz`);
  setText("hold-age", p.age_s === null || p.age_s === undefined ? "–" : `${fixed(p.age_s * 1000, 0)} ms`);
  setText("hold-pos", triple(p.position_m));
  setText("hold-att", p.quaternion ? rollPitchYaw(p.quaternion).map((a) => a.toFixed(1)).join(", ") : "–");
  const sim = p.simulated || { running: false };
  setText("hold-drone-state", sim.running ? `flying (seed ${sim.params.seed})` : sim.last_error ? `stopped: ${sim.last_error}` : "stopped");
  el("hold-drone-start").disabled = sim.running;
  el("hold-drone-stop").disabled = !sim.running;
  setText("hold-tool", toolInWorld() ? triple(toolInWorld()) : "–");
}

// The tool tip in the world [m] as the server says it (through the latest pose and the
// tip measured at that request: never a pose and a tip from two polls); null without one.
function toolInWorld() {
  return live(hold.pose) ? hold.pose.tool_world_m : null;
}

// Polled only while the panel is on screen (and the tab shown): nothing asked otherwise.
let onScreen = false;

async function pollPose() {
  if (!document.hidden && onScreen) {
    try {
      hold.pose = await get("/api/mav/pose");
      renderPose();
    } catch {
      // offline: the status banner says so; the next poll tries again
    }
  }
  setTimeout(pollPose, POSE_POLL_MS);
}

// ---- the simulated drone ----
function readNumber(id, label, lo, hi) {
  const input = el(id);
  const parsed = parseDecimal(input.value);
  const bad = parsed.error || (parsed.value < lo || parsed.value > hi ? `must be ${lo} to ${hi}` : null);
  input.setAttribute("aria-invalid", bad ? "true" : "false");
  if (bad) throw new Error(`${label} ${bad}`);
  return parsed.value;
}

async function startDrone(event) {
  event.preventDefault();
  let body;
  try {
    body = {
      running: true,
      drift_m: readNumber("hold-drift", "Drift", 0, 200) / 1000,
      tilt_deg: readNumber("hold-tilt", "Tilt", 0, 20),
      seed: Math.round(readNumber("hold-seed", "Seed", 0, 4294967295)),
    };
  } catch (err) {
    say(`${err.message}: nothing was sent.`, true);
    return;
  }
  try {
    await postControl("/api/mav/simulated", body);
    say("Simulated drone flying: its pose feeds the pose input.");
  } catch (err) {
    say(operatorText(err).text, true);
  }
}

async function stopDrone() {
  try {
    await postControl("/api/mav/simulated", { running: false });
    say("Simulated drone stopped: its pose goes stale, then lost (a hold on it stops).");
  } catch (err) {
    say(operatorText(err).text, true);
  }
}

function chooseSource() {
  el("hold-drone").hidden = source() !== "simulated";
}

// ---- the hold ----
function here() {
  const tool = toolInWorld();
  if (!tool) {
    say("No live drone pose: the tool's place in the world is unknown.", true);
    return;
  }
  ["x", "y", "z"].forEach((a, k) => { el(`hold-goal-${a}`).value = (tool[k] * 1000).toFixed(1); });
  say("Goal set to where the tool is in the world now.");
}

// The typed goal, checked; throws an operator message, nothing sent.
async function checkedHold() {
  const goal = ["x", "y", "z"].map((a) => readNumber(`hold-goal-${a}`, `Goal ${a}`, -1e6, 1e6) / 1000);
  const duration = readNumber("hold-duration", "Duration", 1, 600);
  const body = {
    duration_s: duration, position_m: goal, source: "external",
    latency_compensation: el("hold-compensate").checked,
  };
  if (wrist.enabled && el("hold-heading").value.trim() !== "") {
    body.heading_rad = readNumber("hold-heading", "Heading", -360, 360) * Math.PI / 180;
  }
  const p = hold.pose;
  if (!p || p.state !== "ok") {
    throw new Error(`The drone's pose is ${p ? STATES[p.state] || p.state : "unknown"}: a hold needs a fresh pose (start the simulated drone or a pose stream)`);
  }
  const inBase = baseInWorld(p).inverse(goal);
  let inside = inBase.every((v) => Math.abs(v) <= REACH_M);
  if (inside) {
    const q = new URLSearchParams({ x_m: inBase[0], y_m: inBase[1], z_m: inBase[2] });
    try {
      inside = (await get(`/api/workspace/nearest?${q}`)).inside; // a question: moves nothing
    } catch (err) {
      throw new Error(`The goal could not be checked (${operatorText(err).text})`);
    }
  }
  if (!inside) {
    ["x", "y", "z"].forEach((a) => el(`hold-goal-${a}`).setAttribute("aria-invalid", "true"));
    throw new Error("That goal is outside the arm's reach at the drone's pose now (press Here for the tool's place)");
  }
  return body;
}

async function beginHold(event) {
  event.preventDefault();
  let body;
  try {
    body = await checkedHold();
  } catch (err) {
    say(`${err.message}: nothing was sent.`, true);
    return;
  }
  try {
    const run = await postControl("/api/tests/hold", body);
    hold.runId = run.run_id;
    hold.samples = [];
    el("hold-verdict").hidden = true;
    el("hold-stop").disabled = false;
    say(`Holding the tool at (${triple(body.position_m)}) mm in the world: run ${run.run_id}.`);
    openStream();
    watchRun(run.run_id);
  } catch (err) {
    say(operatorText(err).text, true);
  }
}

async function stopHold() {
  if (!hold.runId) return;
  try {
    await postControl(`/api/runs/${encodeURIComponent(hold.runId)}/abort`, {});
    say("Hold stopped: the arm holds where it is.");
  } catch (err) {
    say(operatorText(err).text, true);
  }
}

// ---- the run's verdict after ----
const REPORT_TRIES = 60; // a report is drawn after the run ends: asked for once a second

async function watchRun(runId, tries = REPORT_TRIES) {
  let run = null;
  try {
    run = await get(`/api/runs/${encodeURIComponent(runId)}`);
  } catch {
    // offline a moment: asked again below
  }
  if (hold.runId !== runId) return;
  if (run && run.state !== "running") showVerdict(run);
  const ended = run && run.state !== "running";
  if (!ended || (!run.has_report && tries > 0)) {
    setTimeout(() => watchRun(runId, ended ? tries - 1 : tries), 1000);
  }
}

function showVerdict(run) {
  el("hold-stop").disabled = true;
  closeStream();
  const box = el("hold-verdict");
  const w = run.stats && run.stats.world;
  const state = el("hold-run-state");
  // stopped by the operator is a normal end (neutral); a fault or a refusal is red
  const byOperator = run.state === "aborted" && /by the operator/.test(run.reason || "");
  const said = run.reason && !run.reason.startsWith(run.state) ? `${run.state}: ${run.reason}` : run.reason;
  state.textContent = byOperator ? "stopped by the operator" : said || run.state;
  state.className = run.state === "done" ? "ok" : byOperator ? "" : "bad";
  setText("hold-run-id", run.run_id);
  setText("hold-rmse", w ? ["x", "y", "z"].map((a) => mm(w[a].rmse_m, 2)).join(" / ") : "–");
  setText("hold-max", w ? ["x", "y", "z"].map((a) => mm(w[a].max_abs_m, 2)).join(" / ") : "–");
  setText("hold-outside", w && typeof w.outside_s === "number" ? `${fixed(w.outside_s, 2)} s` : "–");
  const report = el("hold-report-link");
  report.hidden = !run.has_report;
  report.href = `/api/runs/${encodeURIComponent(run.run_id)}/report.png`;
  box.hidden = false;
  box.dataset.run = run.run_id;
}

// ---- the world-frame plot ----
function openStream() {
  closeStream();
  const socket = new WebSocket(telemetryUrl(STREAM_HZ));
  socket.onmessage = (event) => {
    const m = JSON.parse(event.data);
    if (m.mode !== "hold-world" || !m.world || m.world.measured_m.some((v) => v === null)) return;
    hold.samples.push({ t: m.t, goal: m.world.goal_m, tool: m.world.measured_m, error: m.world.error_m });
    const cut = m.t - WINDOW_S;
    while (hold.samples.length && hold.samples[0].t < cut) hold.samples.shift();
  };
  hold.socket = socket;
  drawTimer = setInterval(draw, DRAW_MS);
}

function closeStream() {
  if (hold.socket) hold.socket.close();
  hold.socket = null;
  clearInterval(drawTimer);
  draw();
}

// Three strips (x, y, z): the world goal (dashed) and the tool in the world (solid) [mm],
// each scaled to its own range around the goal; the error now beside them.
function draw() {
  const canvas = el("hold-plot");
  const s = hold.samples;
  if (s.length === hold.drawn && canvas.dataset.samples) return;
  hold.drawn = s.length;
  const ctx = canvas.getContext("2d");
  const { width, height } = canvas;
  ctx.clearRect(0, 0, width, height);
  canvas.dataset.samples = String(s.length);
  ctx.font = "11px system-ui, sans-serif";
  if (s.length < 2) {
    ctx.fillStyle = COLOURS.axis;
    ctx.fillText("the world-frame tracking shows here while a hold runs", 12, height / 2);
    return;
  }
  const pad = { left: 70, right: 10, top: 6, bottom: 22 };
  const strip = (height - pad.top - pad.bottom) / 3;
  const t0 = s[0].t;
  const t1 = s[s.length - 1].t;
  const x = (t) => pad.left + ((t - t0) / Math.max(t1 - t0, 1e-6)) * (width - pad.left - pad.right);
  ["x", "y", "z"].forEach((axis, k) => {
    const goal = s.map((v) => v.goal[k] * 1000);
    const tool = s.map((v) => v.tool[k] * 1000);
    const centre = goal[goal.length - 1];
    const half = Math.max(1, ...tool.map((v) => Math.abs(v - centre)), ...goal.map((v) => Math.abs(v - centre))) * 1.1;
    const top = pad.top + k * strip;
    const y = (v) => top + strip / 2 - ((v - centre) / half) * (strip / 2 - 4);
    ctx.strokeStyle = COLOURS.grid;
    ctx.strokeRect(pad.left, top, width - pad.left - pad.right, strip);
    ctx.fillStyle = COLOURS.axis;
    ctx.textAlign = "right";
    ctx.textBaseline = "middle";
    ctx.fillText(`${axis} ${centre.toFixed(1)}`, pad.left - 4, top + strip / 2);
    ctx.fillText(`±${half.toFixed(1)} mm`, pad.left - 4, top + strip / 2 + 13);
    const line = (values, colour, dash, lineWidth) => {
      ctx.strokeStyle = colour;
      ctx.lineWidth = lineWidth;
      ctx.setLineDash(dash);
      ctx.beginPath();
      // a gap in the samples (the pose stale: the hold froze, nothing in the world frame)
      // stays a gap, never a straight line across it
      values.forEach((v, i) => (i && s[i].t - s[i - 1].t <= GAP_S
        ? ctx.lineTo(x(s[i].t), y(v)) : ctx.moveTo(x(s[i].t), y(v))));
      ctx.stroke();
      ctx.setLineDash([]);
    };
    line(goal, COLOURS.goal, [5, 4], 1.5);
    line(tool, COLOURS.tool, [], 1.5);
  });
  ctx.textAlign = "center";
  ctx.textBaseline = "top";
  ctx.fillStyle = COLOURS.axis;
  ctx.fillText(`the last ${fixed(t1 - t0, 1)} s`, (pad.left + width) / 2, height - pad.bottom + 6);
  const last = s[s.length - 1].error;
  const norm = Math.hypot(...last);
  setText("hold-error", `${triple(last, 2)} (|e| ${mm(norm, 2)})`);
  canvas.dataset.errorMm = (norm * 1000).toFixed(3);
}

export function startHold() {
  window.deltadash = Object.assign(window.deltadash || {}, { hold });
  document.querySelectorAll('input[name="hold-source"]').forEach((r) => r.addEventListener("change", chooseSource));
  el("hold-drone").addEventListener("submit", startDrone);
  el("hold-drone-stop").addEventListener("click", stopDrone);
  el("hold-here").addEventListener("click", here);
  el("hold-form").addEventListener("submit", beginHold);
  el("hold-stop").addEventListener("click", stopHold);
  chooseSource();
  draw();
  new IntersectionObserver((entries) => {
    onScreen = entries.some((e) => e.isIntersecting);
  }).observe(document.querySelector("section.hold"));
  pollPose();
}
