// Operator commands: e-stop (Space / Esc), torque, reset, go-to, and hold-to-move jogs from
// the pad, the arrow keys and a gamepad (they move only while held: see startHold).

import { postControl, takeLease, token } from "./api.js";
import { showError, showMessage, setText } from "./ui.js";

const KEY_AXES = {
  ArrowRight: [0, 1], ArrowLeft: [0, -1], ArrowUp: [1, 1], ArrowDown: [1, -1],
  PageUp: [2, 1], PageDown: [2, -1],
};
const HEARTBEAT_MS = 50; // a held jog's heartbeat; the server brakes 150 ms after the last
const GAMEPAD_PERIOD_MS = 50;
const DEADZONE = 0.15;
const DEADMAN_BUTTON = 4; // LB on standard-mapping pads
let maxSpeed = 0.5; // [m/s], /api/info's jog limit

// A command that needs the control lease (api.js takes it on first use); another holder is
// taken over only if the operator agrees.
export async function command(path, body) {
  try {
    return await postControl(path, body);
  } catch (err) {
    if (err.status === 409 && err.message.includes("control is held by")) {
      if (window.confirm(`${err.message}\n\nTake control?`)) {
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
// reaction comes after. Each press is recorded (window.deltadash.estops, Unix ms) so a test
// can compare it with the server's arrival time (GET /api/status's estop_received_unix_s).
const estops = [];
window.deltadash = Object.assign(window.deltadash || {}, { estops });

export function estop(event = null) {
  const headers = token() ? { Authorization: `Bearer ${token()}` } : {};
  const sent = fetch("/api/estop", { method: "POST", headers, keepalive: true, priority: "high" });
  const sentMs = Date.now();
  // event.timeStamp is when the input arrived, before any wait for the main thread
  const eventMs = event ? performance.timeOrigin + event.timeStamp : sentMs;
  estops.push({ source: event ? event.type : "call", event_unix_ms: eventMs, sent_unix_ms: sentMs });
  sent
    .then((response) => {
      if (!response.ok) throw new Error(`E-stop refused by the server (HTTP ${response.status})`);
      showMessage("E-stop", "error");
    })
    .catch((err) => showError(new Error(`E-stop not confirmed: ${err.message}`)));
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

function axisVelocity(axis, sign) {
  const velocity = [0, 0, 0];
  velocity[axis] = sign * speedMS();
  return velocity;
}

function typing(target) {
  return target instanceof HTMLInputElement && target.type !== "checkbox" ||
    target instanceof HTMLSelectElement || target instanceof HTMLTextAreaElement;
}

function onKey(event) {
  // E-stop wins over everything, even a focused button (Space would otherwise click it).
  if (event.key === "Escape" || (event.key === " " && !typing(event.target))) {
    if (!event.repeat) estop(event); // first, before anything else (a held key sends one)
    event.preventDefault();
    event.stopImmediatePropagation();
    return;
  }
  const axis = KEY_AXES[event.key];
  if (!axis || typing(event.target)) return;
  // Keys jog only while this page has focus and the operator has switched keyboard jog on.
  if (!document.getElementById("jog-keys").checked || !document.hasFocus()) return;
  event.preventDefault();
  if (event.repeat) return; // the hold's own heartbeat keeps it going
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
  on("torque-off", "/api/torque", { enabled: false });
  on("reset", "/api/reset");
  const pad = document.querySelector(".pad");
  pad.addEventListener("pointerdown", (event) => {
    const spec = event.target.closest("[data-jog]")?.dataset.jog;
    if (!spec) return;
    event.target.setPointerCapture?.(event.pointerId); // the release comes here, wherever it is
    startHold("pad", axisVelocity("xyz".indexOf(spec[0]), spec[1] === "+" ? 1 : -1));
  });
  for (const type of ["pointerup", "pointercancel", "lostpointercapture"]) {
    pad.addEventListener(type, () => releaseHold("pad"));
  }
  document.getElementById("goal-form").addEventListener("submit", (event) => {
    event.preventDefault();
    const form = new FormData(event.target);
    const goal = ["x", "y", "z"].map((k) => Number(form.get(k)) / 1000);
    command("/api/goal", { position_m: goal })
      .then(() => showMessage("Goal accepted"))
      .catch(showError);
  });
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
