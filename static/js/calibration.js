// The calibration panel: the guided procedure of docs/calibration.md from the page. Its
// steps (plan, move and measure, fit, report) with the current one marked and a progress
// bar; start (poses, what to fit, the measurement source: the simulator's own motion capture,
// a motion-capture stream on the pose input, or probe touches of a plate at a height in mm),
// abort; the fit's report (RMSE before / after and on the held-out poses in mm, the
// observability, the fitted offsets in degrees and legs in mm, the verdict, report.png
// inline) and apply (after a confirmation that says what changes) or leave the model as it
// is. The run is followed by polling GET /api/calibration/{id} while it runs (one request at
// a time); nothing else runs on a timer.

import { get, getBlob } from "./api.js";
import { askConfirm, command } from "./control.js";
import { operatorText, parseDecimal, setText, showError, showMessage } from "./ui.js";

export const STEPS = ["planned", "moving", "fitting", "report"];
const RUNNING = ["planned", "moving", "fitting"];
const POLL_MS = 500;
const LIMITS = { poses: { min: 12, max: 300 }, plateMm: { min: -2000, max: 0 } };
// what each measurement source is and what it needs (shown beside the choice)
const SOURCES = {
  external: {
    label: "the robot's own measurement",
    needs: "The simulator measures its platform itself (its motion capture, with 0.3 mm of noise): " +
      "nothing else is needed. A real robot has no measurement of its own: use a motion-capture stream.",
  },
  "pose-input": {
    label: "motion-capture stream",
    needs: "Needs a motion-capture marker on the platform streamed to the pose input as body " +
      "\"platform\" (UDP JSON, or the pose WebSocket), positions in metres, the base still " +
      "(docs/calibration.md, \"Motion capture through the pose input\").",
  },
  probe: {
    label: "probe touches of a plate",
    needs: "Touches of a flat plate at the height given (heights only): the simulated robot " +
      "has a probe; other robots have no probe input yet.",
  },
};
const VERDICT = {
  done: "better than the model in use on the held-out poses: it may be applied",
  refused: "not better than the model in use on the held-out poses: it is not offered",
  applied: "applied: the controller uses it",
  failed: "failed",
  aborted: "was aborted by the operator: the arm holds where it was stopped",
};

const view = { run: null, reportFor: null, dismissed: null, said: null };
const panel = { run: () => view.run, said: null }; // window.deltadash.calibration (tests)
let polling = false;
let reportUrl = null;

const el = (id) => document.getElementById(id);
const mm = (m, digits = 2) => (m === null || m === undefined ? "–" : `${(m * 1000).toFixed(digits)} mm`);
const degText = (rad, digits = 3) => `${rad >= 0 ? "+" : ""}${((rad * 180) / Math.PI).toFixed(digits)}°`;

function say(text, kind = "") {
  const out = el("cal-message");
  out.textContent = text;
  out.className = `proc-message ${kind}`;
}

// A server error in the page's words: the procedure's own fields and routes named as the
// panel names them, the rest as everywhere (ui.js operatorText).
export function procedureWords(err, what) {
  let raw = String(err && err.message ? err.message : err);
  raw = raw
    .replace(/POST \/api\/calibration\/[\w-]+\/abort to stop it/g, "press Abort in the Calibration panel to stop it")
    .replace(/POST \/api\/tuning\/[\w-]+\/abort to stop it/g, "press Abort in the Tuning panel to stop it")
    .replace(/POST \/api\/tuning\/revert first/g, "press Revert in the Tuning panel first")
    .replace(/^run ([\w-]+) is (\w+): only a done run can be applied/, `${what} $1 is $2: only a finished run can be applied`)
    .replace(/^run ([\w-]+) is applied already/, `${what} $1 is applied already`);
  if (raw.startsWith("measurement: no external measurement")) {
    raw = "this robot has no measurement of its own: stream motion capture of the platform to the pose input and choose \"motion-capture stream\"";
  } else if (raw.startsWith("measurement: no fresh motion-capture pose")) {
    raw = "no fresh motion capture of the platform: start the stream (body \"platform\") and see its state under the choice";
  } else if (raw.startsWith("source: this backend has no probe")) {
    raw = "this robot has no probe input (the simulated robot has one): choose a motion measurement";
  }
  raw = raw.replace(/^plate_z_m: /, "plate height: ");
  return operatorText({ message: raw, status: err && err.status }).text;
}

// ---- the form ----

// The typed parameters as the API's body, or the first problem in the page's words (each bad
// field marked).
export function calibrationBody(form) {
  const mark = (input, bad) => input.setAttribute("aria-invalid", bad ? "true" : "false");
  const poses = form.elements.poses;
  const text = poses.value.trim();
  let error = null;
  if (!/^\d+$/.test(text)) {
    error = `poses: ${text ? `"${poses.value}" is not a whole number` : "is empty"} (${LIMITS.poses.min} to ${LIMITS.poses.max})`;
  } else if (Number(text) < LIMITS.poses.min || Number(text) > LIMITS.poses.max) {
    error = `poses: ${text} is outside ${LIMITS.poses.min} to ${LIMITS.poses.max}`;
  }
  mark(poses, error);
  const source = form.elements.source.value;
  const body = { poses: Number(text), parameters: form.elements.parameters.value };
  const plate = form.elements.plate;
  let plateError = null;
  if (source === "probe") {
    const parsed = parseDecimal(plate.value);
    if (parsed.error) {
      plateError = `plate height: ${parsed.error}`;
    } else if (!(parsed.value < LIMITS.plateMm.max && parsed.value > LIMITS.plateMm.min)) {
      plateError = `plate height: ${parsed.value} mm is not below the base (between ${LIMITS.plateMm.min} and ${LIMITS.plateMm.max} mm, z up)`;
    }
    body.source = "probe";
    body.plate_z_m = parsed.error ? null : parsed.value / 1000;
    body.fit_plate_z = form.elements.fitPlate.checked;
  } else {
    body.source = "motion";
    body.measurement = source;
  }
  mark(plate, plateError);
  error = error || plateError;
  return error ? { error } : body;
}

function showSource() {
  const source = el("cal-form").elements.source.value;
  setText("cal-source-needs", SOURCES[source].needs);
  el("cal-probe-fields").hidden = source !== "probe";
  el("cal-stream").hidden = source !== "pose-input";
  if (source === "pose-input") platformStream();
}

// The platform stream's health, when that source is chosen (one request).
async function platformStream() {
  try {
    const s = await get("/api/mav/pose?body=platform");
    const age = s.age_s === null || s.age_s === undefined ? "" : `, ${(s.age_s * 1000).toFixed(0)} ms old`;
    const rate = s.rate_hz ? `, ${s.rate_hz.toFixed(0)} Hz` : "";
    setText("cal-stream", `platform stream: ${s.state}${age}${rate} (${s.accepted} poses taken)`);
  } catch (err) {
    setText("cal-stream", `platform stream: ${procedureWords(err, "calibration")}`);
  }
}

async function start(event) {
  event.preventDefault();
  const body = calibrationBody(el("cal-form"));
  if (body.error) {
    say(`Not started: ${body.error}`, "bad");
    showMessage(`Not started: ${body.error}`, "error");
    return;
  }
  el("cal-start").disabled = true;
  say("planning the poses…", "muted");
  try {
    const { run_id: id } = await command("/api/calibration/run", body);
    view.dismissed = null;
    showMessage(`Calibration ${id} started`);
    await follow(id);
  } catch (err) {
    const words = procedureWords(err, "calibration");
    say(`Not started: ${words}`, "bad");
    showMessage(`Not started: ${words}`, "error", { detail: err.message });
  } finally {
    render();
  }
}

async function abort() {
  const run = view.run;
  if (!run || !RUNNING.includes(run.state)) return;
  try {
    view.run = await command(`/api/calibration/${run.run_id}/abort`);
    showMessage(`Calibration ${run.run_id} aborted: the arm holds where it is`);
  } catch (err) {
    showMessage(procedureWords(err, "calibration"), "error", { detail: err.message });
  }
  render();
}

// ---- apply / leave ----

// What an apply changes, in the page's words (the confirmation and the panel say it).
export function applyText(run) {
  const p = run.parameters;
  const offsets = p.joint_offsets_rad.map((o, k) => `joint ${k + 1} ${degText(o)}`).join(", ");
  let text = `Apply calibration ${run.run_id}? The controller adds the joint offsets ${offsets} to every joint it reads from now on`;
  if (run.parameters_fitted === "geometry") {
    const legs = [0, 1, 2].map((k) => `leg ${k + 1}: upper link ${(p.L_m[k] * 1000).toFixed(2)}, rod ${(p.l_m[k] * 1000).toFixed(2)}, base radius ${(p.R_m[k] * 1000).toFixed(2)} mm`);
    text += `, and uses each leg's fitted lengths as its robot model (${legs.join("; ")})`;
  }
  return `${text}. Written to the config file if the server runs from one. Nothing moves.`;
}

async function apply() {
  const run = view.run;
  if (!run || run.state !== "done") return;
  const text = applyText(run);
  panel.said = text;
  if (!(await askConfirm(text, "Apply"))) {
    say("not applied: the model in use is unchanged", "muted");
    return;
  }
  try {
    const applied = await command(`/api/calibration/${run.run_id}/apply`);
    panel.applied = applied;
    const where = applied.config_written ? ` and written to ${applied.config_written}` : "";
    showMessage(`Calibration ${run.run_id} applied${where}`);
    view.run = await get(`/api/calibration/${run.run_id}`);
  } catch (err) {
    const words = procedureWords(err, "calibration");
    say(`Not applied: ${words}`, "bad");
    showMessage(`Not applied: ${words}`, "error", { detail: err.message });
  }
  render();
}

function leave() {
  if (!view.run) return;
  view.dismissed = view.run.run_id;
  say(`calibration ${view.run.run_id} left unapplied: the model in use is unchanged`, "muted");
  render();
}

// ---- following the run ----

async function follow(id) {
  view.run = await get(`/api/calibration/${id}`);
  render();
  if (polling) return;
  polling = true;
  let followed = false; // the loop saw a run running: say how it ended
  try {
    // the run shown, whichever it is now (a run started while this loop waited is followed
    // on by it)
    while (view.run && RUNNING.includes(view.run.state)) {
      followed = true;
      await new Promise((resolve) => { setTimeout(resolve, POLL_MS); });
      const shown = view.run.run_id;
      try {
        const body = await get(`/api/calibration/${shown}`);
        if (view.run.run_id === shown) view.run = body; // not one started meanwhile
      } catch (err) {
        say(`cannot read the run: ${procedureWords(err, "calibration")}`, "bad");
      }
      render();
    }
  } finally {
    polling = false;
  }
  const r = view.run;
  if (followed && r && r.state !== "aborted") {
    const said = r.state === "done" ? "done: see its report below" : `${r.state}${r.error ? `: ${procedureWords({ message: r.error }, "calibration")}` : ""}`;
    showMessage(`Calibration ${r.run_id} ${said}`, ["failed"].includes(r.state) ? "error" : "info");
  }
}

// The step a run is at: its index in STEPS (the report once it has ended).
export function stepOf(run) {
  if (!run) return -1;
  const k = STEPS.indexOf(run.state);
  return k >= 0 ? k : STEPS.length - 1;
}

// Progress 0..1: planning 0, each pose measured, the fit, the end.
export function progressOf(run) {
  if (!run) return 0;
  const poses = run.progress.poses || 1;
  if (run.state === "planned") return 0;
  if (run.state === "moving") return 0.9 * (run.progress.pose / poses);
  if (run.state === "fitting") return 0.95;
  return run.state === "aborted" || run.state === "failed" ? 0.9 * (run.progress.pose / poses) : 1;
}

function renderSteps(run) {
  const at = stepOf(run);
  const ended = run && !RUNNING.includes(run.state);
  el("cal-steps").querySelectorAll("li").forEach((li, k) => {
    const current = k === at;
    li.className = k < at || (ended && current && run.state !== "failed" && run.state !== "aborted") ? "done" : current ? "current" : "";
    if (current) li.setAttribute("aria-current", "step"); else li.removeAttribute("aria-current");
  });
  const bar = el("cal-progress");
  bar.value = progressOf(run);
  const p = run ? run.progress : null;
  const state = run ? run.state : "";
  setText("cal-progress-text", !run ? "no run yet"
    : `${run.run_id}: ${state}${p ? `, pose ${p.pose} of ${p.poses}` : ""}`);
}

const row = (label, value, id) => `<tr><th scope="row">${label}</th><td id="${id}">${value}</td></tr>`;

function renderReport(run) {
  const box = el("cal-report");
  if (!run) { box.hidden = true; return; }
  box.hidden = false;
  const why = run.error && run.state === "failed" ? `: ${procedureWords({ message: run.error }, "calibration")}` : "";
  const verdict = ["failed", "aborted"].includes(run.state) ? `The run ${VERDICT[run.state]}` : `The fit is ${VERDICT[run.state] || run.state}`;
  setText("cal-verdict", `${verdict}${why}`);
  el("cal-verdict").className = `proc-verdict ${run.state === "done" || run.state === "applied" ? "ok" : ["refused", "failed"].includes(run.state) ? "bad" : "muted"}`;
  const fitPoses = run.progress.poses - run.holdout_poses;
  const rows = [
    row("source", run.source === "probe" ? `probe touches of a plate at ${mm(run.plate_z_m, 1)}` : SOURCES[run.measurement || "external"].label, "cal-r-source"),
    row("fitted", run.parameters_fitted === "geometry" ? "joint offsets and leg lengths" : "joint offsets", "cal-r-fitted"),
    row("poses", `${fitPoses} fitted, ${run.holdout_poses} held out`, "cal-r-poses"),
    row("RMSE, fitted poses", `${mm(run.rmse_before_m)} → ${mm(run.rmse_after_m)}`, "cal-r-rmse"),
    row("RMSE, held-out poses", `${mm(run.holdout_rmse_before_m)} → ${mm(run.holdout_rmse_m)}`, "cal-r-holdout"),
    row("condition number", run.condition_number === null ? "–" : run.condition_number.toFixed(1), "cal-r-condition"),
    row("not observable", run.unobservable.length ? run.unobservable.join(", ") : "none: every fitted parameter is seen", "cal-r-unobservable"),
  ];
  if (run.unobservable_combinations.length) rows.push(row("directions not pinned", run.unobservable_combinations.join("; "), "cal-r-combinations"));
  if (run.parameters) {
    const p = run.parameters;
    rows.push(row("joint offsets", p.joint_offsets_rad.map((o) => degText(o)).join(", "), "cal-r-offsets"));
    if (run.parameters_fitted === "geometry") {
      const lengths = (values) => values.map((v) => (v * 1000).toFixed(2)).join(", ") + " mm";
      rows.push(row("upper links L", lengths(p.L_m), "cal-r-L"));
      rows.push(row("rods l", lengths(p.l_m), "cal-r-l"));
      rows.push(row("base radii R", lengths(p.R_m), "cal-r-R"));
    }
  }
  if (run.plate_error_m !== null && run.plate_error_m !== undefined) rows.push(row("plate height error", mm(run.plate_error_m, 3), "cal-r-plate"));
  if (run.measurement_frame) {
    const f = run.measurement_frame;
    rows.push(row("measurement frame", `origin (${f.position_m.map((v) => (v * 1000).toFixed(1).replace(/^-(0\.0)$/, "$1")).join(", ")}) mm, roll/pitch/yaw ${f.rpy_rad.map((v) => degText(v, 2)).join(", ")}`, "cal-r-frame"));
  }
  el("cal-figures").innerHTML = `<tbody>${rows.join("")}</tbody>`;
  el("cal-figures").dataset.run = run.run_id;
  const done = run.state === "done" && view.dismissed !== run.run_id;
  el("cal-apply").disabled = !done;
  el("cal-leave").disabled = !done;
  showReportImage(run);
}

async function showReportImage(run) {
  const img = el("cal-report-img");
  if (!run.files.includes("report.png")) {
    img.hidden = true;
    return;
  }
  if (view.reportFor === run.run_id) return;
  view.reportFor = run.run_id;
  try {
    const blob = await getBlob(`/api/calibration/${run.run_id}/report.png`);
    if (reportUrl) URL.revokeObjectURL(reportUrl);
    reportUrl = URL.createObjectURL(blob);
    img.src = reportUrl;
    img.alt = `calibration ${run.run_id}: each pose's residual before and after the fit`;
    img.dataset.run = run.run_id;
    img.hidden = false;
  } catch (err) {
    view.reportFor = null;
    say(`report image: ${procedureWords(err, "calibration")}`, "bad");
  }
}

function render() {
  const run = view.run;
  const running = Boolean(run && RUNNING.includes(run.state));
  el("cal-start").disabled = running;
  el("cal-abort").disabled = !running;
  renderSteps(run);
  renderReport(run);
  if (run && running) say(run.state === "moving" ? "moving through the poses and measuring at rest…" : `${run.state}…`, "muted");
  else if (run && run.run_id !== view.said) { // the run has ended: its verdict says how
    view.said = run.run_id;
    say("", "");
  }
}

// The newest run this server knows (a reload finds the run in progress, or the last report).
async function latest() {
  try {
    const runs = await get("/api/calibration");
    if (runs.length) await follow(runs[0].run_id);
  } catch {
    // the server is not up yet: the panel starts empty
  }
}

function openImage() {
  const img = el("cal-report-img");
  const box = document.getElementById("report-box");
  if (!img.src || !box) return;
  document.getElementById("report-img").src = img.src;
  setText("report-title", `Calibration ${img.dataset.run}`);
  document.getElementById("report-open").href = img.src;
  if (!box.open) box.showModal();
}

export function startCalibration() {
  window.deltadash = Object.assign(window.deltadash || {}, { calibration: panel });
  const form = el("cal-form");
  form.addEventListener("submit", start);
  form.elements.source.addEventListener("change", showSource);
  el("cal-abort").addEventListener("click", abort);
  el("cal-apply").addEventListener("click", apply);
  el("cal-leave").addEventListener("click", leave);
  el("cal-report-img").addEventListener("click", openImage);
  showSource();
  render();
  latest();
}
