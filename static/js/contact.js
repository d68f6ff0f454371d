// Contact (docs/dashboard.md "Contact (issue 33)"): the tip's contact force estimate live
// (GET /api/status "contact": the force the tip applies on what it touches, base frame, with
// its 1-sigma error), the limits in force (GET /api/contact), a touch (a guarded move that
// stops at a set force: POST /api/contact/touch) and its result, a compliant press (POST
// /api/contact/press, frame "base") and Stop (POST /api/stop: the arm holds where it is
// commanded, torque on, nothing to reset; the e-stop stays the page's own button). The page
// speaks N, mm, mm/s and s; every body is sent in SI (N, m, m/s, s). Every typed value is
// checked here, before anything is sent; the server checks again.

import { get, postControl, mm, fixed } from "./api.js";
import { operatorText, parseDecimal, setText, showMessage } from "./ui.js";

const AXES = { "-z": [0, 0, -1], "+z": [0, 0, 1], "-x": [-1, 0, 0], "+x": [1, 0, 0], "-y": [0, -1, 0], "+y": [0, 1, 0] };
const MAX_SPEED_MM_S = 100; // the server's limit on a touch's speed (0.1 m/s)
const MAX_TRAVEL_MM = 300; // ... and on its travel (0.3 m)
const MAX_DURATION_S = 3600; // ... and on a press's duration

const el = (id) => document.getElementById(id);
// what the page knows: GET /api/contact's limits and defaults, the last touch, the touch this
// tab started (followed until it ends), whether a GET /api/contact is on its way
export const contact = { limits: null, defaults: null, touch: null, following: null, asking: false, estimate: null };

// ---- the live estimate (each status poll) ----
// ``value`` to ``digits`` decimals, "0.00" (not "-0.00") for a value that rounds to zero
function num(value, digits = 2) {
  if (value === null || value === undefined) return "–";
  const text = Number(value).toFixed(digits);
  return /^-0\.?0*$/.test(text) ? text.slice(1) : text;
}
const triple = (v, digits = 2, scale = 1) => (v && v.every((c) => c !== null) ? v.map((c) => num(c * scale, digits)).join(", ") : "–");

export function onContactStatus(status) {
  const c = status && status.contact;
  if (!c) return;
  contact.estimate = c;
  const live = el("contact-live");
  live.dataset.valid = c.valid ? "true" : "false";
  if (c.valid) {
    setText("contact-mag", `${fixed(c.magnitude_n, 2)} N`);
    setText("contact-force", triple(c.force_n));
    setText("contact-std", `± ${triple(c.std_n)}`);
    setText("contact-why", "");
  } else {
    setText("contact-mag", "–");
    setText("contact-force", "–");
    setText("contact-std", "–");
    setText("contact-why", `no estimate: ${c.reason || "unknown"}`);
  }
  setText("contact-mode", status.mode === "touch" ? "touching" : status.mode === "press" ? "pressing" : "");
  if (status.mode === "touch" || contact.following) refresh();
}

// ---- GET /api/contact: limits, defaults, the last touch ----
async function refresh() {
  if (contact.asking) return;
  contact.asking = true;
  try {
    const answer = await get("/api/contact");
    contact.limits = answer.limits;
    contact.defaults = answer.defaults;
    renderLimits();
    renderTouch(answer.touch);
  } catch {
    // offline: the status banner says so; the next status tries again
  } finally {
    contact.asking = false;
  }
}

function renderLimits() {
  const l = contact.limits;
  if (!l) return;
  const collision = l.collision_stop ? `collision stop at ${fixed(l.collision_force_n, 1)} N` : "collision stop off";
  setText("contact-limits", `force limit ${fixed(l.force_limit_n, 1)} N, contact seen at ${fixed(l.detect_force_n, 1)} N, ${collision}`);
}

function renderTouch(touch) {
  contact.touch = touch;
  if (!touch) return;
  el("contact-result").hidden = false;
  const outcome = el("contact-outcome");
  setText("contact-outcome", touch.outcome);
  outcome.dataset.outcome = touch.outcome;
  outcome.className = touch.outcome === "contact" ? "ok" : touch.outcome === "touching" ? "" : "bad";
  const point = touch.contact_point_m;
  setText("contact-point", triple(point, 2, 1000));
  setText("contact-touch-force", triple(touch.force_n));
  setText("contact-peak", touch.peak_force_n === null ? "–" : `${fixed(touch.peak_force_n, 2)} N`);
  setText("contact-travel", touch.travel_m === null ? "–" : `${mm(touch.travel_m, 2)} mm`);
  if (contact.following && touch.source_id === contact.following && touch.outcome !== "touching") {
    contact.following = null;
    const said = touch.outcome === "contact"
      ? `Touch: contact at (${el("contact-point").textContent}) mm, peak ${fixed(touch.peak_force_n, 2)} N.`
      : `Touch ended: ${touch.outcome}.`;
    showMessage(said, touch.outcome === "contact" ? "info" : "error");
  }
}

// ---- reading the forms ----
// The value of field ``id`` (a decimal point or comma), within [lo, hi] (``open``: lo itself
// refused); an empty optional field is null. Throws naming the field; the field turns red.
function read(id, label, lo, hi, { open = false, optional = false, unit = "" } = {}) {
  const input = el(id);
  if (optional && !input.value.trim()) {
    input.setAttribute("aria-invalid", "false");
    return null;
  }
  const parsed = parseDecimal(input.value);
  let bad = parsed.error || null;
  if (!bad && (open ? parsed.value <= lo : parsed.value < lo)) bad = `must be ${open ? "over" : "at least"} ${lo}${unit}`;
  if (!bad && parsed.value > hi) bad = `must be at most ${hi}${unit}`;
  input.setAttribute("aria-invalid", bad ? "true" : "false");
  if (bad) throw new Error(`${label} ${bad}`);
  return parsed.value;
}

// The direction chosen in the select ``prefix``-dir (±x ±y ±z) or typed in its three fields.
function direction(prefix) {
  const choice = el(`${prefix}-dir`).value;
  if (choice !== "typed") return AXES[choice];
  const v = ["x", "y", "z"].map((a) => read(`${prefix}-dir-${a}`, `direction ${a}`, -1e6, 1e6));
  if (Math.hypot(...v) < 1e-9) {
    ["x", "y", "z"].forEach((a) => el(`${prefix}-dir-${a}`).setAttribute("aria-invalid", "true"));
    throw new Error("direction must not be zero");
  }
  return v;
}

function showTyped(prefix) {
  el(`${prefix}-typed`).hidden = el(`${prefix}-dir`).value !== "typed";
}

const forceLimit = () => (contact.limits ? contact.limits.force_limit_n : 15);
const detectForce = () => (contact.limits ? contact.limits.detect_force_n : 0);

// Server words in the page's: the API's field names and SI units as the form names them.
const FIELDS = { force_n: "force", speed_m_s: "speed", max_travel_m: "max travel", retract_m: "retract", duration_s: "duration", direction: "direction" };
export function contactWords(err) {
  const raw = String(err && err.message ? err.message : err)
    .replace(/(-?\d+(?:\.\d+)?(?:e-?\d+)?) ?m\/s\b/g, (_, v) => `${Number((Number(v) * 1000).toPrecision(6))} mm/s`)
    .replace(/\b(force_n|speed_m_s|max_travel_m|retract_m|duration_s)\b/g, (_, f) => FIELDS[f]);
  return operatorText({ message: raw, status: err && err.status });
}

function refuse(what, err) {
  showMessage(`${what}: ${err.message}: nothing was sent.`, "error");
}

async function send(what, path, body) {
  try {
    const answer = await postControl(path, body);
    return answer;
  } catch (err) {
    const { text, clearsWhen } = contactWords(err);
    showMessage(`${what} refused: ${text}`, "error", { detail: err.message, clearsWhen });
    return null;
  }
}

// ---- stop (not the e-stop): the touch or press ends, the arm holds ----
async function stopMotion(event) {
  event.preventDefault();
  const answer = await send("Stop", "/api/stop", {});
  if (!answer) return;
  const pushing = contact.estimate && contact.estimate.valid ? contact.estimate.magnitude_n : 0;
  const still = answer.result && pushing > detectForce() ? ` It still pushes ${fixed(pushing, 1)} N: touch or jog away from the surface to release it.` : "";
  showMessage(answer.result ? `Stopped: the arm holds where it is.${still}` : "Nothing was moving.");
}

// ---- touch ----
async function startTouch(event) {
  event.preventDefault();
  let body;
  try {
    const d = direction("contact-touch");
    const force = read("contact-touch-force-n", "Touch force", detectForce(), forceLimit(), { open: true, unit: " N" });
    const speed = read("contact-touch-speed", "Touch speed", 0, MAX_SPEED_MM_S, { open: true, unit: " mm/s" });
    const travel = read("contact-touch-travel", "Max travel", 0, MAX_TRAVEL_MM, { open: true, unit: " mm" });
    const retract = read("contact-touch-retract", "Retract", 0, travel, { unit: " mm" });
    body = { direction: d, force_n: force, speed_m_s: speed / 1000, max_travel_m: travel / 1000, retract_m: retract / 1000 };
  } catch (err) {
    refuse("Touch", err);
    return;
  }
  const answer = await send("Touch", "/api/contact/touch", body);
  if (!answer) return;
  contact.following = answer.result.source_id;
  showMessage("Touching: moving until the set force…");
  refresh();
}

// ---- press ----
async function startPress(event) {
  event.preventDefault();
  let body;
  try {
    const d = direction("contact-press");
    const force = read("contact-press-force", "Press force", 0, forceLimit(), { open: true, unit: " N" });
    const duration = read("contact-press-duration", "Duration", 0, MAX_DURATION_S, { open: true, optional: true, unit: " s" });
    body = { direction: d, force_n: force, frame: "base" };
    if (duration !== null) body.duration_s = duration;
  } catch (err) {
    refuse("Press", err);
    return;
  }
  const answer = await send("Press", "/api/contact/press", body);
  if (answer) showMessage(`Pressing ${fixed(body.force_n, 1)} N${body.duration_s ? ` for ${body.duration_s} s` : " until Stop"}.`);
}

function fillDefaults() {
  const d = contact.defaults;
  if (!d) return;
  const put = (id, value) => { if (!el(id).value) el(id).value = value; };
  put("contact-touch-force-n", String(d.force_n));
  put("contact-touch-speed", String(Number((d.speed_m_s * 1000).toPrecision(6))));
  put("contact-touch-travel", String(Number((d.max_travel_m * 1000).toPrecision(6))));
}

export async function startContact() {
  for (const prefix of ["contact-touch", "contact-press"]) {
    el(`${prefix}-dir`).addEventListener("change", () => showTyped(prefix));
    showTyped(prefix);
  }
  el("contact-touch").addEventListener("submit", startTouch);
  el("contact-press").addEventListener("submit", startPress);
  el("contact-stop").addEventListener("click", stopMotion);
  window.deltadash = Object.assign(window.deltadash || {}, { contact });
  await refresh();
  fillDefaults();
}
