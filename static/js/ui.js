// Small page helpers: text updates without layout churn, the message line (toast), and the
// one place server errors become operator wording (mm, degrees, buttons by their names).

let toastTimer = null;
let toastClears = null; // (status) => true once the toast's condition has cleared
let toastShownAt = 0; // performance.now() when it was shown

export function setText(id, text) {
  const el = document.getElementById(id);
  if (el && el.textContent !== text) el.textContent = text;
}

// A message for the operator. ``detail``: the server's own words (a tooltip, and the console);
// ``clearsWhen(status)``: the toast goes as soon as the status says its condition cleared
// (e.g. "e-stop is active" after Reset), not only after its time.
export function showMessage(text, kind = "info", { detail = "", clearsWhen = null } = {}) {
  const toast = document.getElementById("toast");
  toast.textContent = text;
  toast.title = detail ? `server: ${detail}` : "";
  toast.className = `toast ${kind}`;
  toast.hidden = false;
  toastClears = clearsWhen;
  toastShownAt = performance.now();
  clearTimeout(toastTimer);
  // a toast with a condition stays while it holds (e-stop still active); others time out
  if (!clearsWhen) toastTimer = setTimeout(hideToast, kind === "error" ? 8000 : 3000);
}

function hideToast() {
  document.getElementById("toast").hidden = true;
  toastClears = null;
}

// Each status poll: a toast whose condition has cleared goes. ``askedAt``: when that status
// was requested; one asked before the toast was shown may predate its condition.
export function toastStatus(status, askedAt) {
  if (toastClears && askedAt > toastShownAt && toastClears(status)) {
    clearTimeout(toastTimer);
    hideToast();
  }
}

export function showError(err) {
  const { text, clearsWhen } = operatorText(err);
  const detail = err && err.message ? `${err.message}${err.status ? ` (HTTP ${err.status})` : ""}` : "";
  if (detail) console.info("server said:", detail);
  showMessage(text, "error", { detail, clearsWhen });
}

const DECIMAL = /^[+\-\u2212]?(\d+([.,]\d*)?|[.,]\d+)$/;

// A typed decimal number: "12.5", "12,5" (a decimal comma) and "-240" are numbers; "1,234.5",
// "12,5,0", "" and "1e3" are refused with the reason ({ error }), never read another way.
export function parseDecimal(text) {
  const t = String(text).trim().replace("\u2212", "-");
  if (!t) return { error: "is empty" };
  if (!DECIMAL.test(t)) return { error: `"${text}" is not a number (e.g. 12.5 or 12,5)` };
  const value = Number(t.replace(",", "."));
  if (!Number.isFinite(value)) return { error: `"${text}" is not a number` };
  return { value };
}

const METRE_FIELDS = /\b(position|delta|amplitude|offset)_m\b/g;
// other API field names as the page names them: no "phi_rad" or "velocity_m_s" on the page
const FIELD_WORDS = {
  phi_rad: "wrist angle φ", velocity_m_s: "jog velocity", speed_m_s: "speed", joints_rad: "joints",
  duration_s: "duration", lease_id: "control", take_over: "take control",
};
const OTHER_FIELDS = new RegExp(`\\b(${Object.keys(FIELD_WORDS).join("|")})\\b`, "g");

// A servo's gains as the page names them (the API's p, i, d, ff1, ff2: register units).
export const GAIN_NAMES = {
  p: "P gain", i: "I gain", d: "D gain", ff1: "FF1 gain (velocity)", ff2: "FF2 gain (acceleration)",
};
const GAIN_FIELD = /^(p|i|d|ff1|ff2): /;

// "[0.0300, 0.0000, -0.2300] m" -> "(30.0, 0.0, -230.0) mm"; "0.5 m" -> "500.0 mm".
export function metresToMm(text) {
  const num = "-?\\d+(?:\\.\\d+)?(?:e-?\\d+)?";
  return text
    .replace(new RegExp(`\\[\\s*(${num})\\s*,\\s*(${num})\\s*,\\s*(${num})\\s*\\]\\s*m\\b`, "g"),
      (_, x, y, z) => `(${[x, y, z].map((v) => (Number(v) * 1000).toFixed(1)).join(", ")}) mm`)
    .replace(new RegExp(`(${num}) m\\b(?!/)`, "g"), (_, v) => `${(Number(v) * 1000).toFixed(1)} mm`)
    .replace(/(-?\d+(?:\.\d+)?) rad\b(?!\/)/g, (_, v) => `${(Number(v) * 180 / Math.PI).toFixed(1)}°`);
}

// A server error (ApiError: status, message = the detail) in an operator's words, and when
// its condition clears (for the toast). API paths, field names and SI units stay in the API.
export function operatorText(err) {
  const raw = String(err && err.message ? err.message : err);
  if (raw.startsWith("e-stop is active")) {
    return { text: "E-stop is active: press Reset first.", clearsWhen: (s) => !s.estopped };
  }
  if (raw.startsWith("torque is off")) {
    return { text: "Torque is off: press Torque on first.", clearsWhen: (s) => s.torque };
  }
  const fault = raw.match(/^fault: (.*); POST \/api\/reset first$/);
  if (fault) {
    return { text: `Fault: ${metresToMm(fault[1])}. Press Reset first.`, clearsWhen: (s) => !s.faults.length && !s.estopped };
  }
  // control (the lease): the API says how to take it over by the API; the page has a button
  const held = raw.match(/^control is held by '?([^';]+?)'? since ([^;]+?)(;.*)?$/);
  if (held) {
    return { text: `Control is held by ${held[1]} (another tab or program) since ${held[2]}.`, clearsWhen: null };
  }
  if (/take control first/.test(raw)) {
    return { text: "This tab does not have control (it lapsed or was taken): try again to take it.", clearsWhen: null };
  }
  if (raw.startsWith("position_m: outside the workspace")) {
    return { text: "That point is outside the workspace: choose a point inside it.", clearsWhen: null };
  }
  if (raw.startsWith("position_m: no joint solution")) {
    return { text: "The arm cannot reach that point (no joint angles for it).", clearsWhen: null };
  }
  if (err && err.status === 0) return { text: `No answer from the server: ${raw}`, clearsWhen: null };
  if (raw.includes("only while the arm rests")) {
    const what = raw.includes("read") ? "read the servo's gains" : "write gains";
    return { text: `The arm is moving: ${what} once it rests.`, clearsWhen: null };
  }
  if (raw.startsWith("no applied tuning or written gains to revert")) {
    return { text: "Nothing to revert: no gains were written or applied since the server started.", clearsWhen: null };
  }
  if (GAIN_FIELD.test(raw)) {
    const name = GAIN_NAMES[raw.match(GAIN_FIELD)[1]];
    return { text: raw.replace(GAIN_FIELD, `${name}: `).replace("Input should be", "must be"), clearsWhen: null };
  }
  if (raw.startsWith("step_rad: ")) { // a servo's step: the field is the step, in degrees
    const said = raw.replace(/^step_rad: /, "").replace(/^the step is infeasible: /, "")
      .replace(/(\d) deg\b/g, "$1°").replace(/\] deg\b/g, "]°");
    return { text: `Step not possible: ${metresToMm(said)}`, clearsWhen: null };
  }
  let text = raw
    .replace(/POST \/api\/reset first/g, "press Reset first")
    .replace(/POST \/api\/torque \{"enabled": true\} first/g, "press Torque on first")
    .replace(/\(a goal or jog\)/g, "(Go to or jog)");
  text = metresToMm(text).replace(METRE_FIELDS, (_, what) => what === "position" ? "goal" : what)
    .replace(OTHER_FIELDS, (_, field) => FIELD_WORDS[field])
    .replace(/(\d) deg\b/g, "$1°").replace(/\] deg\b/g, "]°");
  text = text.replace(/^infeasible: /, "Not possible: ");
  return { text: text.charAt(0).toUpperCase() + text.slice(1), clearsWhen: null };
}
