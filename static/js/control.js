// Operator commands: e-stop (Space / Esc), torque, reset, go-to, and hold-to-move jogs from
// the pad, the arrow keys and a gamepad (they move only while held: see startHold), or step
// jogs of 0.1 / 1 / 10 mm (one press, one step: see stepJog).

import { get, postControl, takeLease } from "./api.js";
import { isEstopKey, newPressId, postEstop, postListener, typing } from "./estopkey.js";
import { operatorText, parseDecimal, showError, showMessage, setText } from "./ui.js";
import { PHI_STEP_DEG, clampPhi, currentPhiRad, wrist } from "./wrist.js";

const KEY_AXES = {
  ArrowRight: [0, 1], ArrowLeft: [0, -1], ArrowUp: [1, 1], ArrowDown: [1, -1],
  PageUp: [2, 1], PageDown: [2, -1],
};
// with a wrist and keyboard jog on: each press turns the wrist PHI_STEP_DEG (a held key on,
// at most once per PHI_REPEAT_MS)
const PHI_KEYS = { e: 1, "]": 1, q: -1, "[": -1 };
const PHI_REPEAT_MS = 150;
const HEARTBEAT_MS = 50; // a held jog's heartbeat; the server brakes 150 ms after the last
const GAMEPAD_PERIOD_MS = 50;
const DEADZONE = 0.15;
const DEADMAN_BUTTON = 4; // LB on standard-mapping pads
let maxSpeed = 0.5; // [m/s], /api/info's jog limit
let confirmMoveM = 0.05; // [m], /api/info's confirm_move_m: longer typed moves ask first
let homeM = [0, 0, -0.24]; // [m], /api/info's home_m
const CONFIRM_TURN_KEY = "deltadash.confirmTurnDeg";
const CONFIRM_TURN_DEG = 30; // a goal turning the wrist more than this asks first (page setting)
// the operator typed in the Go-to form since its last Go: its fields stop following the robot
let goalTyped = false;
let latest = null; // the last GET /api/status (status.js hands each one here)
// always moving (a goal's or jog's "jog" source stays on at its target: moving only on the way)
const MOVING_MODES = new Set(["move", "move-joints", "test", "hold-world"]);
const MOVING_RAD_S = 0.05; // a joint faster than this counts as moving (torque-off asks)
const ON_THE_WAY_M = 5e-5; // the command this far from the goal, or from the last status's
let previousCommandM = null; // the commanded point [m] in the status before the latest

// A command that needs the control lease (api.js takes it on first use); another holder is
// taken over only if the operator agrees.
export async function command(path, body) {
  try {
    return await postControl(path, body);
  } catch (err) {
    if (err.status === 409 && err.message.includes("control is held by")) {
      // asked in the page (window.confirm would block the page, and its e-stop keys)
      if (await askConfirm(`${operatorText(err).text} Take control from there?`, "Take control")) {
        await takeLease(true);
        return postControl(path, body);
      }
    }
    throw err;
  }
}

// The e-stop never waits: the request leaves first, synchronously from the key or pointer
// event, on its own keepalive fetch at high priority (not behind the page's other requests,
// not after the lease or the token prompt: POST /api/estop needs neither); the page's
// reaction comes after. A second request goes in parallel to the server's e-stop listener
// (its own port and thread, /api/info's estop_port: it does not wait behind the server's
// event loop); both carry the same press id, so the server counts the press once, at its
// first arrival. Each press is recorded (window.deltadash.estops, Unix ms) so a test can
// compare it with the server's arrival time (GET /api/status's estop_received_unix_s).
const estops = [];
window.deltadash = Object.assign(window.deltadash || {}, { estops });
let estopListenerUrl = null; // "http://<this host>:<estop_port>/estop", null: none known

// ``forwarded``: a press the plots' frame took (it had the keyboard focus) and already sent
// to /api/estop itself: { press, event_unix_ms, source }; the page records it and sends it
// by the other paths with the same id.
export function estop(event = null, forwarded = null) {
  const press = forwarded ? forwarded.press : newPressId();
  const requests = forwarded ? [] : [postEstop(press)];
  if (estopListenerUrl) requests.push(postListener(estopListenerUrl, press));
  if (forwarded) requests.push(postEstop(press)); // the frame's own request may not be answered
  const sentMs = Date.now();
  // event.timeStamp is when the input arrived, before any wait for the main thread
  const eventMs = forwarded ? forwarded.event_unix_ms
    : event ? performance.timeOrigin + event.timeStamp : sentMs;
  estops.push({
    source: forwarded ? `plots:${forwarded.source}` : event ? event.type : "call",
    event_unix_ms: eventMs, sent_unix_ms: forwarded ? forwarded.sent_unix_ms : sentMs,
    press, paths: requests.length + (forwarded ? 1 : 0),
  });
  const confirmed = (request) => request.then((response) => {
    if (!response.ok) throw new Error(`E-stop refused by the server (HTTP ${response.status})`);
  });
  Promise.any(requests.map(confirmed))
    .then(() => {
      showMessage("E-stop: nothing moves until Reset", "error", { clearsWhen: (s) => !s.estopped });
    })
    .catch((err) => {
      const first = (err.errors && err.errors[0]) || err;
      showError(new Error(`E-stop not confirmed: ${first.message}`));
    });
  answerConfirm(false); // a pending move is not wanted after an e-stop
  estopCount += 1; // nor one whose check was on its way (goTo)
}

// ---- an in-page confirmation (not window.confirm: that would block the e-stop keys) ----
let pendingConfirm = null;
let estopCount = 0; // e-stops pressed in this tab

function answerConfirm(yes) {
  const resolve = pendingConfirm;
  pendingConfirm = null;
  document.getElementById("confirm").hidden = true;
  if (resolve) resolve(yes);
}

// Ask the operator; resolves true (the yes button) or false (cancel, e-stop, another ask).
export function askConfirm(text, yesLabel) {
  answerConfirm(false);
  setText("confirm-text", text);
  setText("confirm-yes", yesLabel);
  document.getElementById("confirm").hidden = false;
  document.getElementById("confirm-no").focus();
  return new Promise((resolve) => { pendingConfirm = resolve; });
}

// ---- typed goals: decimal point or comma, to 0.01 mm, shown before they are sent ----

// A typed number in mm (ui.js parseDecimal: "12,5" is 12.5), rounded to 0.01 mm.
export function parseMm(text) {
  const parsed = parseDecimal(text);
  return parsed.error ? parsed : { value: Math.round(parsed.value * 100) / 100 };
}

const fmt2 = (v) => v.toFixed(2);
const tripleMm = (p) => `(${p.map(fmt2).join(", ")}) mm`;

// The point the robot is at for a new move [m]: its goal while torque holds it, else measured.
function robotPointM() {
  const s = latest;
  if (!s) return null;
  const goal = s.goal && s.goal.position_m;
  if (s.torque && goal && goal.every((v) => v !== null)) return goal;
  const meas = s.ee && s.ee.position_m;
  return meas && meas.every((v) => v !== null) ? meas : null;
}

function distanceMm(targetMm) {
  const here = robotPointM();
  if (!here) return null;
  return Math.hypot(...targetMm.map((v, i) => v - here[i] * 1000));
}

// The page's setting: a goal that turns the wrist more than this [deg] asks first.
export function confirmTurnDeg() {
  const field = document.getElementById("confirm-turn-deg");
  const parsed = field ? parseDecimal(field.value) : { error: "none" };
  return parsed.error || parsed.value < 0 ? CONFIRM_TURN_DEG : parsed.value;
}

// How far a goal at ``phiDeg`` turns the wrist from the angle a new goal starts at (its
// goal, else where it is) [deg]; null without a wrist or a status.
function wristTurnDeg(phiDeg) {
  if (!wrist.enabled || phiDeg === null || !latest) return null;
  return Math.abs(phiDeg - currentPhiRad(latest) * 180 / Math.PI);
}

// The form's target in mm (and, with a wrist, phiDeg: its phi [deg] to 0.1 deg), or the
// first field's error; marks bad fields.
function formTarget() {
  const form = document.getElementById("goal-form");
  const target = [];
  let error = null;
  for (const k of ["x", "y", "z"]) {
    const input = form.elements[k];
    const parsed = parseMm(input.value);
    input.setAttribute("aria-invalid", parsed.error ? "true" : "false");
    if (parsed.error && !error) error = `${k}: ${parsed.error}`;
    target.push(parsed.value);
  }
  let phiDeg = null;
  if (wrist.enabled) {
    const input = form.elements.phi;
    const parsed = parseDecimal(input.value);
    input.setAttribute("aria-invalid", parsed.error ? "true" : "false");
    if (parsed.error && !error) error = `φ: ${parsed.error}`;
    phiDeg = parsed.error ? null : Math.round(parsed.value * 10) / 10;
  }
  return error ? { error } : { target, phiDeg };
}

// "target (x, y, z) mm at φ 60.0°, distance 12.00 mm, wrist turn 60.0°"
function describeMove(targetMm, phiDeg = null) {
  const d = distanceMm(targetMm);
  const turn = wristTurnDeg(phiDeg);
  const phi = phiDeg === null ? "" : ` at φ ${phiDeg.toFixed(1)}°`;
  return `target ${tripleMm(targetMm)}${phi}` + (d === null ? "" : `, distance ${d.toFixed(2)} mm`) +
    (turn === null ? "" : `, wrist turn ${turn.toFixed(1)}°`);
}

function updateGoalPreview() {
  const out = document.getElementById("goal-preview");
  const { target, phiDeg, error } = formTarget();
  const text = error ? `Not sent: ${error}` : `Go will send: ${describeMove(target, phiDeg)}`;
  if (out.textContent !== text) out.textContent = text;
  out.className = error ? "goal-preview bad" : "goal-preview muted";
}

// Until the operator types, the Go-to fields show where a new goal starts (the goal while
// torque holds the arm, else the measured point; the wrist's goal, else its angle): a tab
// opened after another moved the arm shows where it is now, not its own last value. A field
// with the keyboard focus is left alone. workspace2d.js hears "follow" (nothing typed).
function followRobot() {
  if (goalTyped) return;
  const form = document.getElementById("goal-form");
  const here = robotPointM();
  const values = here ? { x: here[0], y: here[1], z: here[2] } : {};
  let changed = false;
  const put = (name, text) => {
    const input = form.elements[name];
    if (!input || input === document.activeElement || input.value === text) return;
    input.value = text;
    input.setAttribute("aria-invalid", "false");
    changed = true;
  };
  for (const [k, v] of Object.entries(values)) put(k, (v * 1000).toFixed(2));
  if (wrist.enabled && latest) put("phi", (currentPhiRad(latest) * 180 / Math.PI).toFixed(1));
  if (changed) form.dispatchEvent(new CustomEvent("follow"));
}

// Whether the gate accepts ``targetMm`` at ``phiRad`` (GET /api/workspace/nearest): {inside,
// nearestM [m]}; null when it could not be asked (busy, offline: the goal's own check decides).
// Throws the 422 of a bad field (a wrist angle outside its limits).
async function nearestFor(targetMm, phiRad) {
  const [x, y, z] = targetMm.map((v) => String(v / 1000));
  const query = new URLSearchParams({ x_m: x, y_m: y, z_m: z });
  if (wrist.enabled && phiRad !== null) query.set("phi_rad", phiRad.toFixed(6));
  try {
    const answer = await get(`/api/workspace/nearest?${query}`);
    return { inside: answer.inside, nearestM: answer.nearest_m };
  } catch (err) {
    if (err.status === 422) throw err;
    return null;
  }
}

// Go to ``targetMm`` (3 numbers, mm), with a wrist at ``phiDeg`` [deg] (null: the wrist
// keeps its goal). A target the gate refuses offers the nearest point it accepts (the same
// one ``deltadash ik`` gives) before anything is asked or sent; a move longer than
// confirm_move_m, or one turning the wrist more than the page's setting, asks first, naming
// the target, the distance and the turn. Nothing is sent on cancel. Resolves true if the
// goal was accepted.
export async function goTo(targetMm, what = "Go to", phiDeg = null) {
  if (!wrist.enabled) phiDeg = null;
  const phiRad = !wrist.enabled ? null : phiDeg === null ? currentPhiRad(latest) : phiDeg * Math.PI / 180;
  let sendM = targetMm.map((v) => v / 1000);
  let asked = false;
  let check = null;
  const estopsBefore = estopCount;
  try {
    check = await nearestFor(targetMm, phiRad);
  } catch (err) {
    showError(err);
    return false;
  }
  if (estopCount !== estopsBefore) return false; // e-stopped while it was checked
  if (check && !check.inside) {
    const nearMm = check.nearestM.map((v) => v * 1000);
    const away = Math.hypot(...nearMm.map((v, i) => v - targetMm[i]));
    const ok = await askConfirm(`${what}: ${tripleMm(targetMm)} is outside where the arm may go. ` +
      `The nearest point it may go to is ${away.toFixed(1)} mm from it: ${describeMove(nearMm, phiDeg)}. ` +
      "Go there instead?", "Go to nearest");
    if (!ok) {
      showMessage("Move cancelled: nothing was sent");
      return false;
    }
    sendM = check.nearestM;
    targetMm = nearMm;
    asked = true;
  }
  const d = distanceMm(targetMm);
  const turn = wristTurnDeg(phiDeg);
  const limitDeg = confirmTurnDeg();
  const why = [];
  if (d === null) why.push("the robot's position is not known yet");
  else if (d > confirmMoveM * 1000) why.push(`longer than ${(confirmMoveM * 1000).toFixed(0)} mm`);
  if (turn !== null && turn > limitDeg) why.push(`turns the wrist ${turn.toFixed(1)}°, more than ${limitDeg}°`);
  if (why.length && !asked) {
    const ok = await askConfirm(`${what}: ${describeMove(targetMm, phiDeg)} (${why.join("; ")}). Move?`, "Move");
    if (!ok) {
      showMessage("Move cancelled: nothing was sent");
      return false;
    }
  }
  const body = { position_m: sendM };
  // the API's phi_rad defaults to 0: with a wrist it is always sent, so no goal turns it back
  if (wrist.enabled) body.phi_rad = phiRad;
  try {
    await command("/api/goal", body);
    showMessage(`Going to ${tripleMm(targetMm)}${phiDeg === null ? "" : ` at φ ${phiDeg.toFixed(1)}°`}`);
    return true;
  } catch (err) {
    showError(err);
    return false;
  }
}

export function goHome() {
  return goTo(homeM.map((v) => Math.round(v * 1e5) / 100), "Go to the home point");
}

export const homePointM = () => homeM;

export function homeText() {
  return tripleMm(homeM.map((v) => v * 1000));
}

// Whether the arm moves now (a motion running, the command on its way or changing, a joint
// faster than MOVING_RAD_S): torque off asks first, and a software-drawn scene pauses.
export function armMoving(s) {
  if (!s || !s.torque) return false;
  const speeds = (s.joints && s.joints.velocity_rad_s) || [];
  const apart = (a, b) => Boolean(a && b) && a.some((v, i) => v !== null && b[i] !== null && Math.abs(v - b[i]) > ON_THE_WAY_M);
  const onTheWay = apart(s.goal.position_m, s.ee.commanded_m) || apart(s.ee.commanded_m, previousCommandM);
  return MOVING_MODES.has(s.mode) || onTheWay || speeds.some((v) => v !== null && Math.abs(v) > MOVING_RAD_S);
}

async function torqueOff() {
  if (armMoving(latest)) {
    const ok = await askConfirm("The arm is moving. Torque off lets it drop and hang; " +
      "E-STOP stops it instead. Torque off anyway?", "Torque off");
    if (!ok) return;
  }
  command("/api/torque", { enabled: false }).catch(showError);
}

// status.js hands every status here: the robot's point for distances, moving for torque off.
export function controlStatus(s) {
  previousCommandM = latest ? latest.ee.commanded_m : null;
  latest = s;
  followRobot();
  updateGoalPreview(); // the distance and the wrist turn follow the robot as it moves
}

// The step of a step jog [mm] (the pad's and the arrow keys' mode), or null: hold to move.
function jogStepMm() {
  const value = document.getElementById("jog-step")?.value;
  return !value || value === "hold" ? null : Number(value);
}

// One step jog: ``stepMm`` [mm] along axis (0..2) by sign, from where the loop commands,
// through the gate as every jog (POST /api/jog delta_m: a target outside is clamped onto
// the workspace). Resolves true if accepted.
export async function stepJog(axis, sign, stepMm = jogStepMm()) {
  const delta = [0, 0, 0];
  delta[axis] = sign * stepMm / 1000;
  try {
    await command("/api/jog", { delta_m: delta });
    return true;
  } catch (err) {
    showError(err);
    return false;
  }
}

function speedMS() {
  return Math.min(Number(document.getElementById("jog-speed").value) / 1000, maxSpeed);
}

// Hold-to-move: while a key, pad button or the gamepad's deadman is held, the jog's
// velocity is posted every HEARTBEAT_MS; the server brakes 0.15 s after the last
// one (a frozen tab or a lost link stops the robot). Release sends a zero velocity.
// One hold at a time (the latest press wins); one request in flight at most.
const hold = { owner: null, velocity: null, timer: null, inflight: Promise.resolve(), busy: false };

function beat() {
  if (hold.busy || !hold.velocity) return;
  hold.busy = true;
  const owner = hold.owner;
  hold.inflight = command("/api/jog", { velocity_m_s: hold.velocity })
    .catch((err) => {
      if (hold.owner === owner) stopHold(); // refused (torque off, e-stop...): stop trying
      showError(err);
    })
    .finally(() => { hold.busy = false; });
}

// Start holding a jog at ``velocity`` [m/s], or (same owner) change its velocity.
export function startHold(owner, velocity) {
  const fresh = hold.owner !== owner;
  hold.owner = owner;
  hold.velocity = velocity;
  if (!hold.timer) hold.timer = setInterval(beat, HEARTBEAT_MS);
  if (fresh) beat(); // at once on a press; later changes go with the next heartbeat
}

function stopHold() {
  clearInterval(hold.timer);
  hold.timer = null;
  hold.owner = null;
  hold.velocity = null;
}

// Stop the hold ``owner`` started (any hold when owner is null); the zero velocity goes
// after the request in flight, so a late heartbeat cannot restart the jog.
export function releaseHold(owner = null) {
  if (!hold.timer || (owner !== null && hold.owner !== owner)) return;
  stopHold();
  hold.inflight = hold.inflight.then(() =>
    command("/api/jog", { velocity_m_s: [0, 0, 0] }).catch(showError));
}

// ---- the wrist: steps of PHI_STEP_DEG, sent as a goal at the tip's goal (or where it is) ----
const phiJog = { target: null, at: -Infinity }; // the last phi a step sent [rad], and when

// Turn the wrist one step (sign +1 or -1) from its goal (or from the last step, when the
// status has not caught up yet), within its limits. ``repeat``: a held key's auto-repeat,
// at most one step per PHI_REPEAT_MS (each separate press or click steps).
export async function stepPhi(sign, repeat = false) {
  if (!wrist.enabled) return;
  const now = performance.now();
  if (repeat && now - phiJog.at < PHI_REPEAT_MS) return;
  const where = robotPointM();
  if (!where) {
    showMessage("Not sent: the robot's position is not known yet", "error");
    return;
  }
  const base = phiJog.target !== null && now - phiJog.at < 1000 ? phiJog.target : currentPhiRad(latest);
  const phi = clampPhi(base + sign * PHI_STEP_DEG * Math.PI / 180);
  phiJog.target = phi;
  phiJog.at = now;
  try {
    await command("/api/goal", { position_m: where, phi_rad: phi });
  } catch (err) {
    phiJog.target = null;
    showError(err);
  }
}

function axisVelocity(axis, sign) {
  const velocity = [0, 0, 0];
  velocity[axis] = sign * speedMS();
  return velocity;
}

function onKey(event) {
  // E-stop wins over everything, even a focused button (Space would otherwise click it).
  if (isEstopKey(event)) {
    if (!event.repeat) estop(event); // first, before anything else (a held key sends one)
    event.preventDefault();
    event.stopImmediatePropagation();
    // Esc still closes what it closes elsewhere (the report's lightbox), after the e-stop
    if (event.key === "Escape") document.querySelectorAll("dialog[open]").forEach((d) => d.close());
    return;
  }
  const phiSign = wrist.enabled ? PHI_KEYS[String(event.key || "").toLowerCase()] : undefined;
  if (phiSign && !typing(event.target) && document.getElementById("jog-keys").checked && document.hasFocus()) {
    event.preventDefault();
    stepPhi(phiSign, event.repeat); // a held key repeats, at most once per PHI_REPEAT_MS
    return;
  }
  const axis = KEY_AXES[event.key];
  if (!axis || typing(event.target)) return;
  // Keys jog only while this page has focus and the operator has switched keyboard jog on.
  if (!document.getElementById("jog-keys").checked || !document.hasFocus()) return;
  event.preventDefault();
  if (event.repeat) return; // the hold's own heartbeat keeps it going (a step: one per press)
  if (jogStepMm() !== null) {
    stepJog(axis[0], axis[1]);
    return;
  }
  startHold(`key:${event.key}`, axisVelocity(axis[0], axis[1]));
}

function onKeyUp(event) {
  if (KEY_AXES[event.key]) releaseHold(`key:${event.key}`);
}

function bindButtons() {
  // The button stops on press (pointerdown), not on release; a click with no pointer
  // (detail 0: Enter on the focused button) stops too.
  const stopButton = document.getElementById("estop");
  stopButton.addEventListener("pointerdown", (event) => { if (event.button === 0) estop(event); });
  stopButton.addEventListener("click", (event) => { if (event.detail === 0) estop(event); });
  const on = (id, path, body) => document.getElementById(id).addEventListener("click", () =>
    command(path, body).catch(showError));
  on("torque-on", "/api/torque", { enabled: true });
  document.getElementById("torque-off").addEventListener("click", torqueOff);
  on("reset", "/api/reset");
  document.getElementById("confirm-yes").addEventListener("click", () => answerConfirm(true));
  document.getElementById("confirm-no").addEventListener("click", () => answerConfirm(false));
  const pad = document.querySelector(".pad");
  pad.addEventListener("click", (event) => {
    const sign = Number(event.target.closest("[data-phi]")?.dataset.phi);
    if (sign) stepPhi(sign);
    const spec = event.target.closest("[data-jog]")?.dataset.jog;
    if (spec && jogStepMm() !== null) stepJog("xyz".indexOf(spec[0]), spec[1] === "+" ? 1 : -1);
  });
  pad.addEventListener("pointerdown", (event) => {
    const spec = event.target.closest("[data-jog]")?.dataset.jog;
    if (!spec || jogStepMm() !== null) return; // a step jog goes on click: one press, one step
    event.target.setPointerCapture?.(event.pointerId); // the release comes here, wherever it is
    startHold("pad", axisVelocity("xyz".indexOf(spec[0]), spec[1] === "+" ? 1 : -1));
  });
  for (const type of ["pointerup", "pointercancel", "lostpointercapture"]) {
    pad.addEventListener(type, () => releaseHold("pad"));
  }
  const goalForm = document.getElementById("goal-form");
  goalForm.addEventListener("input", () => {
    goalTyped = true; // from now on the fields are the operator's, until a Go is accepted
    updateGoalPreview();
  });
  goalForm.addEventListener("submit", async (event) => {
    event.preventDefault();
    const { target, phiDeg, error } = formTarget();
    updateGoalPreview();
    if (error) {
      showMessage(`Not sent: ${error}`, "error");
      return;
    }
    if (await goTo(target, "Go to", phiDeg)) goalTyped = false; // they follow the goal again
  });
  const turnField = document.getElementById("confirm-turn-deg");
  if (turnField) {
    turnField.value = localStorage.getItem(CONFIRM_TURN_KEY) || String(CONFIRM_TURN_DEG);
    turnField.addEventListener("change", () => {
      const parsed = parseDecimal(turnField.value);
      turnField.setAttribute("aria-invalid", parsed.error || parsed.value < 0 ? "true" : "false");
      if (!parsed.error && parsed.value >= 0) localStorage.setItem(CONFIRM_TURN_KEY, String(parsed.value));
    });
  }
}

// Sticks = velocity, held only while the deadman button is: each poll renews the hold.
function pollGamepad() {
  const pad = [...(navigator.getGamepads ? navigator.getGamepads() : [])].find(Boolean);
  const enabled = document.getElementById("jog-pad").checked;
  if (!pad) {
    releaseHold("gamepad"); // unplugged mid-jog
    setText("gamepad-state", "no gamepad (press a button on it to connect)");
    return;
  }
  const held = Boolean(pad.buttons[DEADMAN_BUTTON]?.pressed);
  setText("gamepad-state", `${pad.id.slice(0, 40)}: ${enabled ? (held ? "jogging" : "hold LB to jog") : "off"}`);
  const axis = (i) => (Math.abs(pad.axes[i] || 0) < DEADZONE ? 0 : pad.axes[i]);
  // left stick x/y (screen up = +y), right stick vertical = z
  const velocity = [axis(0), -axis(1), -axis(3)].map((v) => v * speedMS());
  if (!enabled || !held || !document.hasFocus() || velocity.every((v) => v === 0)) {
    releaseHold("gamepad");
    return;
  }
  startHold("gamepad", velocity); // each poll is the heartbeat, with the stick's velocity now
}

export function startControl(info) {
  if (info && info.jog_max_velocity_m_s) maxSpeed = info.jog_max_velocity_m_s;
  if (info && info.confirm_move_m) confirmMoveM = info.confirm_move_m;
  if (info && Array.isArray(info.home_m)) homeM = info.home_m;
  // the listener speaks plain http: from an https page the browser would block it
  if (info && info.estop_port && location.protocol === "http:") {
    // the robot node's own listener: on its machine (estop_host), else this page's host
    const host = info.estop_host || location.hostname;
    estopListenerUrl = `http://${host}:${info.estop_port}/estop`;
    // keep a connection to it open (the server keeps it alive 30 s): a press then needs no
    // new connection, which cost the browser tens of ms on a loaded machine
    const ready = `http://${host}:${info.estop_port}/ready`;
    const warm = () => fetch(ready, { cache: "no-store" }).catch(() => {});
    warm();
    setInterval(warm, 5000);
  }
  bindButtons();
  window.addEventListener("keydown", onKey, { capture: true }); // before any other handler
  document.addEventListener("keyup", onKeyUp);
  // Losing focus or the tab going hidden ends any hold at once (the server's deadline would
  // anyway), and keyboard jog switches itself off: no stray jogs on return.
  window.addEventListener("blur", () => {
    releaseHold();
    document.getElementById("jog-keys").checked = false;
  });
  document.addEventListener("visibilitychange", () => { if (document.hidden) releaseHold(); });
  setInterval(pollGamepad, GAMEPAD_PERIOD_MS);
}
