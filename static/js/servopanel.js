// The servo panel: one servo at a time (a leg's, or with a wrist the wrist's: its step a
// step of φ within the wrist's limits), as the Dynamixel Wizard gives it. Its gains read
// from the servo (GET /api/servos/{id}/gains), edited within the registers' limits and
// written (POST, the lease), reverted (POST /api/tuning/revert); a step of its joint (POST
// /api/servos/{id}/step, answered with the record) drawn on a canvas 2D. Nothing here runs
// on a timer: a read, a write or a step is one request, and the drawing one pass over a
// second of samples, so the page's thread stays free for the e-stop keys (docs/dashboard.md).

import { get } from "./api.js";
import { command } from "./control.js";
import { GAIN_NAMES, operatorText, parseDecimal, showError, showMessage, setText } from "./ui.js";

const GAINS = ["p", "i", "d", "ff1", "ff2"];
const WHOLE = /^\d+$/;
const COLOURS = { goal: "#868e96", measured: "#d9480f", grid: "#e9ecef", axis: "#495057" };
let servoId = null; // the servo shown
let roles = new Map(); // servo id -> { role: "leg" | "wrist", joint }, from the status
let limits = null; // per gain { min, max }, from the last read
let stepLimitsDeg = { min: 0.5, max: 5 }; // the step's magnitude [deg], from the last read
let busy = false; // a read, write, revert or step on its way: one at a time
const panel = { lastStep: null }; // the last step's answer (window.deltadash.servoPanel)

const el = (id) => document.getElementById(id);
const deg = (rad) => (rad * 180) / Math.PI;

function say(text, kind = "") {
  const out = el("sp-message");
  out.textContent = text;
  out.className = `sp-message ${kind}`;
}

function setBusy(value) {
  busy = value;
  for (const id of ["sp-read", "sp-write", "sp-step-run"]) el(id).disabled = value || servoId === null;
  el("sp-revert").disabled = value || el("sp-revert").dataset.revertable !== "true";
}

// The servo's registers and the loop's gains beside the inputs, the limits under them.
function showGains(body) {
  limits = body.limits;
  const round = (rad) => Math.round(deg(rad) * 100) / 100;
  stepLimitsDeg = { min: round(body.step_rad.min), max: round(body.step_rad.max) };
  const form = el("sp-gains");
  for (const k of GAINS) {
    setText(`sp-servo-${k}`, String(body.servo[k]));
    const differs = body.servo[k] !== body.in_use[k];
    const cell = el(`sp-servo-${k}`);
    cell.className = differs ? "bad" : "";
    cell.title = differs ? `the loop set ${body.in_use[k]}: something else wrote the servo` : "";
    setText(`sp-range-${k}`, `${limits[k].min}–${limits[k].max}`);
    form.elements[k].value = String(body.servo[k]);
    form.elements[k].setAttribute("aria-invalid", "false");
  }
  // the revert is the legs' (the tuning's): the wrist's gains are not kept for it
  const wrist = body.role === "wrist";
  el("sp-revert").dataset.revertable = String(Boolean(body.revertable) && !wrist);
  el("sp-revert").title = wrist
    ? "the revert restores the legs' gains; write the wrist's back by hand"
    : "the gains before the last write or tuning apply, back on the servos";
  const within = body.limits_rad
    ? `, φ within ${deg(body.limits_rad.min).toFixed(1)} to ${deg(body.limits_rad.max).toFixed(1)}°`
    : "";
  setText("sp-step-range", `${stepLimitsDeg.min}–${stepLimitsDeg.max}° either way${within}`);
}

// What a step moves, in words: a leg's joint, or the wrist's φ with the legs held.
function showRole(id) {
  const wrist = (roles.get(id) || {}).role === "wrist";
  setText("sp-step-note", wrist
    ? "a step of φ from where the wrist rests, the legs held"
    : "from where the arm rests, the other joints held");
  setText("sp-legend-what", wrist ? "φ, the wrist's angle" : "the joint's angle");
  el("sp-plot").setAttribute("aria-label", wrist
    ? "the step: the wrist's goal φ (dashed) and measured φ over time"
    : "the step: the joint's goal (dashed) and measured angle over time");
}

// ``quiet``: a read the page made by itself (a servo chosen, the page loaded) says what went
// wrong in the panel only, not in a toast.
async function read({ quiet = false } = {}) {
  if (servoId === null || busy) return;
  setBusy(true);
  say(`reading servo ${servoId}…`, "muted");
  try {
    const body = await get(`/api/servos/${servoId}/gains`);
    showGains(body);
    say(`servo ${servoId}: read from the servo`, "ok");
  } catch (err) {
    say(operatorText(err).text, "bad");
    if (!quiet) showError(err);
  } finally {
    setBusy(false);
  }
}

// The five fields as whole numbers within their registers' limits, or the first one's
// error in the page's words (every bad field is marked).
function gainsBody() {
  const form = el("sp-gains");
  const body = {};
  let error = null;
  for (const k of GAINS) {
    const input = form.elements[k];
    const text = input.value.trim();
    const range = limits ? limits[k] : { min: 0, max: 16383 };
    let problem = null;
    if (!WHOLE.test(text)) {
      problem = text ? `"${input.value}" is not a whole number` : "is empty";
    } else if (Number(text) < range.min || Number(text) > range.max) {
      problem = `${text} is outside ${range.min} to ${range.max}`;
    }
    input.setAttribute("aria-invalid", problem ? "true" : "false");
    if (problem && !error) error = `${GAIN_NAMES[k]}: ${problem} (the register takes ${range.min} to ${range.max})`;
    body[k] = problem ? null : Number(text);
  }
  return error ? { error } : body;
}

async function write(event) {
  event.preventDefault();
  if (servoId === null || busy) return;
  const body = gainsBody();
  if (body.error) {
    say(`Not written: ${body.error}`, "bad");
    showMessage(`Not written: ${body.error}`, "error");
    return;
  }
  setBusy(true);
  try {
    const written = await command(`/api/servos/${servoId}/gains`, body);
    showGains(await get(`/api/servos/${servoId}/gains`)); // what the servo holds now
    const where = written.config_written ? `, and to ${written.config_written}` : "";
    say(`servo ${servoId}: written and read back${where}`, "ok");
    showMessage(`Servo ${servoId}: gains written`);
  } catch (err) {
    say(operatorText(err).text, "bad");
    showError(err);
  } finally {
    setBusy(false);
  }
}

async function revert() {
  if (busy) return;
  setBusy(true);
  try {
    await command("/api/tuning/revert");
    showMessage("Gains reverted");
  } catch (err) {
    say(operatorText(err).text, "bad");
    showError(err);
  } finally {
    setBusy(false);
  }
  await read({ quiet: true });
}

// ---- the step ----

function stepRad() {
  const input = el("sp-step-size");
  const parsed = parseDecimal(input.value);
  let error = parsed.error ? `step: ${parsed.error}` : null;
  if (!error) {
    const size = Math.abs(parsed.value);
    if (size < stepLimitsDeg.min || size > stepLimitsDeg.max) {
      error = `step: ${parsed.value}° is outside ${stepLimitsDeg.min} to ${stepLimitsDeg.max}° either way`;
    }
  }
  input.setAttribute("aria-invalid", error ? "true" : "false");
  return error ? { error } : { value: (parsed.value * Math.PI) / 180 };
}

async function step(event) {
  event.preventDefault();
  if (servoId === null || busy) return;
  const size = stepRad();
  if (size.error) {
    say(`Not stepped: ${size.error}`, "bad");
    showMessage(`Not stepped: ${size.error}`, "error");
    return;
  }
  setBusy(true);
  say(`servo ${servoId}: stepping…`, "muted");
  try {
    const answer = await command(`/api/servos/${servoId}/step`, { step_rad: size.value });
    panel.lastStep = answer;
    draw(answer);
    showFigures(answer);
    const how = answer.state === "done" ? "recorded" : `${answer.state}${answer.reason ? ` (${answer.reason})` : ""}`;
    const done = answer.state === "done";
    say(`servo ${servoId}: step ${how}, run ${answer.run_id}`, done ? "ok" : "bad");
    showMessage(`Servo ${servoId}: step ${how}`, done ? "info" : "error");
  } catch (err) {
    say(operatorText(err).text, "bad");
    showError(err);
  } finally {
    setBusy(false);
  }
}

const ms = (s) => (s === null || s === undefined ? "–" : `${(s * 1000).toFixed(1)} ms`);

function showFigures(answer) {
  const f = answer.figures;
  setText("sp-rise", ms(f.rise_time_s));
  setText("sp-delay", ms(f.delay_s));
  setText("sp-overshoot", f.overshoot_pct === null ? "–" : `${f.overshoot_pct.toFixed(1)} %`);
  setText("sp-settling", f.settling_s === null ? (f.moved_rad === null ? "–" : "not settled") : ms(f.settling_s));
  setText("sp-error", f.steady_error_rad === null ? "–" : `${deg(f.steady_error_rad).toFixed(3)}°`);
  setText("sp-moved", f.moved_fraction === null ? "–" : `${(f.moved_fraction * 100).toFixed(0)} % of the step`);
}

// "Nice" tick values covering [lo, hi]: steps of 1, 2 or 5 times a power of ten.
function ticks(lo, hi, count = 5) {
  const raw = (hi - lo) / count;
  const power = 10 ** Math.floor(Math.log10(raw));
  const stepSize = [1, 2, 5, 10].map((m) => m * power).find((s) => s >= raw) || raw;
  const out = [];
  for (let v = Math.ceil(lo / stepSize) * stepSize; v <= hi + 1e-9; v += stepSize) out.push(v);
  return { values: out, step: stepSize };
}

// The goal (dashed) and the measured angle [deg] over time [ms]: one pass, no animation.
function draw(answer) {
  const canvas = el("sp-plot");
  const ctx = canvas.getContext("2d");
  const { width, height } = canvas;
  const pad = { left: 52, right: 12, top: 12, bottom: 30 };
  ctx.clearRect(0, 0, width, height);
  const t = answer.t_s.map((v) => v * 1000);
  const series = { goal: answer.goal_rad.map(deg), measured: answer.measured_rad.map(deg) };
  canvas.dataset.samples = String(t.length);
  if (t.length < 2) {
    ctx.fillStyle = COLOURS.axis;
    ctx.fillText("no samples recorded", pad.left, height / 2);
    return;
  }
  const all = series.goal.concat(series.measured);
  let lo = Math.min(...all);
  let hi = Math.max(...all);
  const margin = Math.max((hi - lo) * 0.08, 0.05);
  lo -= margin;
  hi += margin;
  const t0 = t[0];
  const t1 = t[t.length - 1];
  const x = (v) => pad.left + ((v - t0) / (t1 - t0)) * (width - pad.left - pad.right);
  const y = (v) => pad.top + ((hi - v) / (hi - lo)) * (height - pad.top - pad.bottom);
  ctx.font = "11px system-ui, sans-serif";
  ctx.lineWidth = 1;
  const yt = ticks(lo, hi);
  const digits = Math.max(0, -Math.floor(Math.log10(yt.step)));
  ctx.textAlign = "right";
  ctx.textBaseline = "middle";
  for (const v of yt.values) {
    ctx.strokeStyle = COLOURS.grid;
    ctx.beginPath(); ctx.moveTo(pad.left, y(v)); ctx.lineTo(width - pad.right, y(v)); ctx.stroke();
    ctx.fillStyle = COLOURS.axis;
    ctx.fillText(`${v.toFixed(digits)}°`, pad.left - 4, y(v));
  }
  ctx.textAlign = "center";
  ctx.textBaseline = "top";
  for (const v of ticks(t0, t1, 6).values) {
    ctx.strokeStyle = COLOURS.grid;
    ctx.beginPath(); ctx.moveTo(x(v), pad.top); ctx.lineTo(x(v), height - pad.bottom); ctx.stroke();
    ctx.fillStyle = COLOURS.axis;
    ctx.fillText(`${Math.round(v)}`, x(v), height - pad.bottom + 4);
  }
  ctx.fillText("t [ms] from the step", (pad.left + width - pad.right) / 2, height - 14);
  const line = (values, colour, dash, widthPx) => {
    ctx.strokeStyle = colour;
    ctx.lineWidth = widthPx;
    ctx.setLineDash(dash);
    ctx.beginPath();
    values.forEach((v, k) => (k ? ctx.lineTo(x(t[k]), y(v)) : ctx.moveTo(x(t[k]), y(v))));
    ctx.stroke();
    ctx.setLineDash([]);
  };
  line(series.goal, COLOURS.goal, [5, 4], 1.5);
  line(series.measured, COLOURS.measured, [], 2);
  canvas.dataset.drawn = answer.run_id;
}

function chooseServo(id) {
  servoId = id;
  el("sp-servo").value = String(id);
  showRole(id);
  setBusy(busy);
  read({ quiet: true });
}

// The legs' operating mode and Goal Current per leg [A], read-only: in current-based
// position (Dynamixel mode 5) each joint's current, and so its torque, stays under it.
function modeText(s) {
  if (!s.servo_mode || !Array.isArray(s.goal_current_a)) return "";
  const mode = s.servo_mode === "current_based_position" ? "current-based position (mode 5)"
    : "position (mode 3)";
  const currents = s.goal_current_a.map((a) => `${a.toFixed(3)}`).join(", ");
  return `mode: ${mode} · goal current per leg: ${currents} A`;
}

// Each status: the servo list (every servo on the bus with its role: the legs', then the
// wrist's), once; the first servo is read at once.
export function onServoStatus(s) {
  setText("sp-mode", modeText(s));
  const select = el("sp-servo");
  const servos = s.servos || s.joints.servo_ids.map((id, k) => ({ id, role: "leg", joint: k + 1 }));
  if (select.options.length !== servos.length) {
    roles = new Map(servos.map((v) => [v.id, v]));
    select.innerHTML = servos.map((v) => `<option value="${v.id}">servo ${v.id} ` +
      `(${v.role === "wrist" ? "wrist, φ" : `joint ${v.joint}`})</option>`).join("");
    if (servoId === null && servos.length) chooseServo(servos[0].id);
    else if (servoId !== null) select.value = String(servoId);
  }
}

export function startServoPanel() {
  window.deltadash = Object.assign(window.deltadash || {}, { servoPanel: panel });
  el("sp-servo").addEventListener("change", (event) => chooseServo(Number(event.target.value)));
  el("sp-read").addEventListener("click", () => read());
  el("sp-gains").addEventListener("submit", write);
  el("sp-revert").addEventListener("click", revert);
  el("sp-step").addEventListener("submit", step);
  setBusy(false);
}
