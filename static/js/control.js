// Operator commands: e-stop (Space / Esc), torque, reset, jog pad and keys, gamepad, go-to.

import { post, postControl, takeLease } from "./api.js";
import { showError, showMessage, setText } from "./ui.js";

const KEY_AXES = {
  ArrowRight: [0, 1], ArrowLeft: [0, -1], ArrowUp: [1, 1], ArrowDown: [1, -1],
  PageUp: [2, 1], PageDown: [2, -1],
};
const GAMEPAD_PERIOD_MS = 50; // velocity jog as steps at 20 Hz
const DEADZONE = 0.15;
const DEADMAN_BUTTON = 4; // LB on standard-mapping pads
let gamepadBusy = false;
let keyJogBusy = false;
let jogSpeed = 0.05; // [m/s] at full stick, capped by /api/info's jog limit

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

export function estop() {
  post("/api/estop").then(() => showMessage("E-stop", "error")).catch(showError);
}

function stepM() {
  return Number(document.getElementById("step").value) / 1000;
}

export function jog(axis, sign, size = stepM()) {
  const delta = [0, 0, 0];
  delta[axis] = sign * size;
  return command("/api/jog", { delta_m: delta }).catch(showError);
}

function typing(target) {
  return target instanceof HTMLInputElement && target.type !== "checkbox" ||
    target instanceof HTMLSelectElement || target instanceof HTMLTextAreaElement;
}

function onKey(event) {
  // E-stop wins over everything, even a focused button (Space would otherwise click it).
  if (event.key === "Escape" || (event.key === " " && !typing(event.target))) {
    event.preventDefault();
    estop();
    return;
  }
  const axis = KEY_AXES[event.key];
  if (!axis || typing(event.target)) return;
  // Keys jog only while this page has focus and the operator has switched keyboard jog on.
  if (!document.getElementById("jog-keys").checked || !document.hasFocus()) return;
  event.preventDefault();
  // a held key repeats ~30 times a second: one jog in flight at most, so none pile up
  if (keyJogBusy) return;
  keyJogBusy = true;
  jog(axis[0], axis[1]).finally(() => { keyJogBusy = false; });
}

function bindButtons() {
  document.getElementById("estop").addEventListener("click", estop);
  const on = (id, path, body) => document.getElementById(id).addEventListener("click", () =>
    command(path, body).catch(showError));
  on("torque-on", "/api/torque", { enabled: true });
  on("torque-off", "/api/torque", { enabled: false });
  on("reset", "/api/reset");
  document.querySelector(".pad").addEventListener("click", (event) => {
    const spec = event.target.closest("[data-jog]")?.dataset.jog;
    if (spec) jog("xyz".indexOf(spec[0]), spec[1] === "+" ? 1 : -1);
  });
  document.getElementById("goal-form").addEventListener("submit", (event) => {
    event.preventDefault();
    const form = new FormData(event.target);
    const goal = ["x", "y", "z"].map((k) => Number(form.get(k)) / 1000);
    command("/api/goal", { position_m: goal })
      .then(() => showMessage("Goal accepted"))
      .catch(showError);
  });
}

// Sticks = velocity: each period send the step the stick asks for, only while the deadman is held.
function pollGamepad() {
  const pad = [...(navigator.getGamepads ? navigator.getGamepads() : [])].find(Boolean);
  const enabled = document.getElementById("jog-pad").checked;
  if (!pad) {
    setText("gamepad-state", "no gamepad (press a button on it to connect)");
    return;
  }
  const held = Boolean(pad.buttons[DEADMAN_BUTTON]?.pressed);
  setText("gamepad-state", `${pad.id.slice(0, 40)}: ${enabled ? (held ? "jogging" : "hold LB to jog") : "off"}`);
  if (!enabled || !held || !document.hasFocus()) return;
  const axis = (i) => (Math.abs(pad.axes[i] || 0) < DEADZONE ? 0 : pad.axes[i]);
  const dt = GAMEPAD_PERIOD_MS / 1000;
  // left stick x/y (screen up = +y), right stick vertical = z
  const delta = [axis(0), -axis(1), -axis(3)].map((v) => v * jogSpeed * dt);
  if (gamepadBusy || delta.every((v) => v === 0)) return;
  // one request in flight at most, so a slow link cannot queue up motion
  gamepadBusy = true;
  command("/api/jog", { delta_m: delta }).catch(showError).finally(() => { gamepadBusy = false; });
}

export function startControl(info) {
  if (info && info.jog_max_velocity_m_s) jogSpeed = Math.min(jogSpeed, info.jog_max_velocity_m_s);
  bindButtons();
  document.addEventListener("keydown", onKey);
  // Keyboard jog switches itself off when the page loses focus: no stray jogs on return.
  window.addEventListener("blur", () => { document.getElementById("jog-keys").checked = false; });
  setInterval(pollGamepad, GAMEPAD_PERIOD_MS);
}
