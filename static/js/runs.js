// The sinusoid test form (preview, start, abort, progress) and the runs table.

import { get, post, mm, fixed } from "./api.js";
import { command } from "./control.js";
import { escape } from "./status.js";
import { showError, showMessage, setText } from "./ui.js";

const RUNS_POLL_MS = 2000;
const PREVIEW_DELAY_MS = 300;
let active = null; // { id, duration, timedSince }
let previewTimer = null;

// Form fields (mm, deg) -> the API's body (m, rad).
function sinusoidBody() {
  const f = new FormData(document.getElementById("sine-form"));
  const triple = (name, scale) => [0, 1, 2].map((i) => Number(f.get(`${name}${i}`)) * scale);
  return {
    amplitude_m: triple("amp", 1e-3), frequency_hz: triple("freq", 1),
    phase_rad: triple("phase", Math.PI / 180), offset_m: triple("off", 1e-3),
    duration_s: Number(f.get("duration")), feedforward: f.get("feedforward") === "on",
  };
}

async function preview() {
  const out = document.getElementById("sine-preview");
  try {
    const c = await post("/api/tests/sinusoid/check", sinusoidBody());
    const speed = c.peak_joint_speed_rad_s === null ? "–" : fixed(c.peak_joint_speed_rad_s, 2);
    const head = `peak joint speed ${speed} rad/s (limit ${fixed(c.joint_speed_limit_rad_s, 1)}), ` +
      `peak platform speed ${fixed(c.peak_speed_m_s, 2)} m/s: `;
    out.textContent = head + (c.feasible ? "feasible" : c.detail);
    out.className = c.feasible ? "preview ok" : "preview bad";
  } catch (err) {
    out.textContent = err.message;
    out.className = "preview bad";
  }
}

function schedulePreview() {
  clearTimeout(previewTimer);
  previewTimer = setTimeout(preview, PREVIEW_DELAY_MS);
}

async function start(event) {
  event.preventDefault();
  const body = sinusoidBody();
  try {
    const { run_id } = await command("/api/tests/sinusoid", body);
    active = { id: run_id, duration: body.duration_s, timedSince: null };
    showMessage(`Run ${run_id} started`);
    refreshRuns();
  } catch (err) {
    showError(err);
  }
}

function abort() {
  if (active) command(`/api/runs/${active.id}/abort`).then(refreshRuns).catch(showError);
}

// Progress through the timed part, from the loop's phase in status (approach, timed, stop).
// Feasibility depends on where the robot starts: re-check when its state changes.
let previewKey = "";

export function onStatus(s) {
  const key = `${s.mode}|${s.torque}|${s.estopped}|${s.faults.length}`;
  if (key !== previewKey && s.mode !== "test") {
    previewKey = key;
    schedulePreview();
  }
  const bar = document.getElementById("run-progress");
  const running = Boolean(active) && s.mode === "test";
  document.getElementById("sine-abort").disabled = !running;
  bar.hidden = !running;
  if (!running) {
    setText("run-phase", "");
    return;
  }
  if (s.phase === "timed" && active.timedSince === null) active.timedSince = performance.now();
  const done = active.timedSince === null ? 0 : (performance.now() - active.timedSince) / 1000;
  bar.value = s.phase === "stop" ? 1 : Math.min(done / active.duration, 1);
  bar.textContent = `${Math.round(bar.value * 100)} %`;
  setText("run-phase", `run ${active.id}: ${s.phase || "starting"} ${Math.round(bar.value * 100)} %`);
}

const triple = (t, key) => (t ? ["x", "y", "z"].map((a) => mm(t[a]?.[key], 2)).join(" / ") : "–");

function runRow(run) {
  // a hold run is judged in the world frame (thesis Table 6.3), the others by tracking
  const t = run.stats && (run.stats.world || run.stats.tracking);
  const under = t ? ["x", "y", "z"].map((a) => `${fixed(100 * t[a].share_under_1mm, 0)}%`).join(" / ") : "–";
  const base = `/api/runs/${encodeURIComponent(run.run_id)}`;
  const links = [["report.png", "report"], ["log.mcap", "MCAP"], ["log.csv", "CSV"]]
    .filter(([name]) => name !== "report.png" || run.has_report)
    .map(([name, label]) => `<a href="${base}/${name}" target="_blank" rel="noopener">${label}</a>`)
    .join(" ");
  const reason = run.reason ? ` title="${escape(run.reason)}"` : ""; // long reasons as a tooltip
  return `<tr data-run="${escape(run.run_id)}"><td>${escape(run.run_id)}</td><td>${escape(run.kind)}${run.stats && run.stats.world ? " (world)" : ""}</td>` +
    `<td class="${run.state === "done" ? "ok" : run.state === "aborted" ? "bad" : ""}"${reason}>${escape(run.state)}</td>` +
    `<td class="num">${triple(t, "rmse_m")}</td><td class="num">${triple(t, "max_abs_m")}</td>` +
    `<td class="num">${under}</td><td>${links}</td></tr>`;
}

export async function refreshRuns() {
  try {
    const runs = await get("/api/runs");
    const html = runs.map(runRow).join("") || `<tr><td colspan="7" class="muted">no runs yet</td></tr>`;
    const body = document.getElementById("run-rows");
    if (body.innerHTML !== html) body.innerHTML = html;
    if (active && runs.some((r) => r.run_id === active.id && r.state !== "running")) active = null;
    // a run started elsewhere (CLI, the 3D scene, another tab) can be followed and aborted too
    const running = runs.find((r) => r.state === "running");
    if (!active && running) {
      const p = running.params;
      active = { id: running.run_id, duration: p.duration_s || p.times_s?.at(-1) || 1, timedSince: null };
    }
  } catch {
    // the status poll shows the connection banner; keep the last table
  }
}

export function startRuns() {
  const form = document.getElementById("sine-form");
  form.addEventListener("submit", start);
  form.addEventListener("input", schedulePreview);
  document.getElementById("sine-abort").addEventListener("click", abort);
  preview();
  refreshRuns();
  setInterval(refreshRuns, RUNS_POLL_MS);
  setText("sine-preview", "checking…");
}
