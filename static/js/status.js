// Header, faults and the servo table from GET /api/status, polled; connection banner.

import { get, mm, deg, fixed } from "./api.js";
import { command, controlStatus, goHome, homePointM, homeText } from "./control.js";
import { showError, setText, toastStatus } from "./ui.js";

const POLL_MS = 200;
const STALE_MS = 1000; // values older than this are greyed and marked stale
const HANGING_BELOW_M = 0.1; // measured this far below the home point: the arm hangs
let lastStatusAt = null; // performance.now() of the last status answer
// The link's round trip: each status poll's request to answer [ms], the last LINK_SAMPLES of
// them; their median over LINK_SLOW_MS says "link slow: 450 ms" in the header's link fact
// (the page then lags by that much: moves and jogs still stop on the server's own deadline).
const LINK_SAMPLES = 5;
const LINK_SLOW_MS = 300;
const roundTrips = [];
const BACKENDS = { sim: "simulator", emulated: "emulated bus", dynamixel: "real servos" };
export const state = { status: null, online: false, streamOnline: false, why: "", listeners: [] };

function setOnline(online, why) {
  state.online = online;
  if (!online) state.why = why;
  updateConnection();
}

// HTTP (status poll) and the telemetry stream can fail separately; either shows the banner.
export function setStreamOnline(online) {
  state.streamOnline = online;
  updateConnection();
}

// The median round trip of the last polls [ms], or null before LINK_SAMPLES of them.
export function linkRoundTripMs() {
  if (roundTrips.length < LINK_SAMPLES) return null;
  const sorted = [...roundTrips].sort((a, b) => a - b);
  return sorted[Math.floor(sorted.length / 2)];
}

function noteRoundTrip(ms) {
  roundTrips.push(ms);
  if (roundTrips.length > LINK_SAMPLES) roundTrips.shift();
}

function updateConnection() {
  const ok = state.online && state.streamOnline;
  const conn = document.getElementById("conn");
  // the server answers, but its robot node does not (503 "robot offline: ...")
  const robotOffline = !state.online && state.why.startsWith("robot offline");
  const trip = linkRoundTripMs();
  const slow = ok && trip !== null && trip > LINK_SLOW_MS;
  conn.title = trip === null ? "" : `status round trip ${trip.toFixed(0)} ms (median of the last ${LINK_SAMPLES})`;
  conn.textContent = slow
    ? `link slow: ${(Math.round(trip / 10) * 10).toFixed(0)} ms`
    : ok
    ? "connected"
    : state.online
      ? "no telemetry"
      : robotOffline
        ? "robot offline"
        : "offline";
  conn.className = slow ? "warn" : ok ? "ok" : "bad";
  const banner = document.getElementById("banner");
  banner.hidden = ok;
  if (robotOffline) {
    const why = state.why.replace(/^robot offline: /, "");
    banner.textContent = `Robot offline: ${why}. The server keeps trying to reach it…`;
  } else if (!state.online) {
    banner.textContent = `Connection to the server lost (${state.why}). Reconnecting…`;
  } else if (!ok) {
    banner.textContent = "Telemetry stream disconnected. Reconnecting…";
  }
}

function renderHeader(s) {
  const kind = BACKENDS[s.backend] || s.backend;
  const backend = s.backend_description ? `${kind}: ${s.backend_description}` : kind;
  setText("backend", backend);
  document.getElementById("backend").title = backend; // the header cuts long descriptions
  const mode = document.getElementById("mode");
  mode.textContent = s.phase ? `${s.mode} (${s.phase})` : s.mode;
  mode.className = s.estopped || s.mode === "fault" ? "bad" : s.mode === "idle" ? "" : "ok";
  setText("torque", s.torque ? "on" : "off");
  setText("loop", `${fixed(s.loop.measured_hz, 0)} / ${fixed(s.loop.target_hz, 0)} Hz`);
  setText("jitter", `${fixed(s.loop.jitter_p99_ms, 2)} ms`);
  renderPose(s.pose);
  document.body.classList.toggle("estopped", Boolean(s.estopped));
}

// Hold-in-world's pose input: none until a source sends; its age matters (staleness).
function renderPose(pose) {
  const el = document.getElementById("pose");
  // shown once a pose source has sent something: the header stays one line otherwise
  el.parentElement.hidden = !pose || pose.state === "none";
  if (el.parentElement.hidden) return;
  el.textContent = `${pose.state} ${fixed(pose.age_s * 1000, 0)} ms, ${fixed(pose.rate_hz, 0)} Hz`;
  el.className = pose.state === "ok" ? "ok" : "bad";
  el.title = `drone pose input (hold in world): ${pose.source || "no"} source, state, age, rate`;
}

// Notices (about the last command: "starting from the measured position") and warnings
// are not faults: a neutral strip of their own, not the red one.
function renderNotices(s) {
  const strip = document.getElementById("notices");
  if (!strip) return;
  const items = [];
  if (s.warning) items.push(`<li class="warn">${escape(s.warning)}</li>`);
  if (s.notice) items.push(`<li>${escape(s.notice)}</li>`);
  const html = items.join("");
  if (strip.innerHTML !== html) strip.innerHTML = html;
  strip.hidden = items.length === 0;
}

function renderFaults(s) {
  const list = document.getElementById("faults");
  const items = s.faults.map((f) => {
    const who = f.servo_id === null || f.servo_id === undefined ? f.source : `servo ${f.servo_id}`;
    const times = f.count > 1 ? ` <span class="muted">(×${f.count})</span>` : "";
    return `<li><strong>${escape(who)}</strong>: ${escape(f.reason)}${times}</li>`;
  });
  if (s.faults_dropped) items.push(`<li class="muted">${s.faults_dropped} older faults not shown</li>`);
  if (s.estopped) items.unshift("<li><strong>E-stop engaged</strong>: nothing moves until Reset</li>");
  const html = items.join("");
  if (list.innerHTML !== html) list.innerHTML = html;
  list.hidden = items.length === 0;
  renderNotices(s);
}

const known = (v) => Boolean(v) && v.every((x) => x !== null && x !== undefined);

// The loop has a setpoint (so a tracking error means something) only while torque holds the
// arm, nothing stopped it and there is a goal: otherwise command - measured is a stale figure.
export function hasSetpoint(s) {
  return s.torque && !s.estopped && !s.faults.length && known(s.goal.position_m);
}

function renderPosition(s) {
  const triple = (v) => (known(v) ? v.map((x) => mm(x, 2)).join(", ") + " mm" : "–");
  setText("pos-meas", triple(s.ee.position_m));
  setText("pos-goal", triple(s.goal.position_m));
  const setpoint = hasSetpoint(s);
  setText("pos-err", setpoint ? triple(s.ee.error_m) : "–");
  document.getElementById("pos-err").title = setpoint ? "goal minus measured" : "no setpoint (torque off or stopped): no error";
}

// First steps: a relaxed arm (torque off), or one hanging below the workspace, says what to do.
function renderFirstSteps(s) {
  const panel = document.getElementById("first-steps");
  const meas = s.ee.position_m;
  const homeZ = homePointM()[2];
  const hanging = known(meas) && meas[2] < homeZ - HANGING_BELOW_M;
  const show = !s.estopped && !s.faults.length && (!s.torque || hanging);
  panel.hidden = !show;
  if (!show) return;
  const where = known(meas) ? ` at z = ${mm(meas[2], 0)} mm` : "";
  setText("first-steps-why", s.torque
    ? `The arm is below the workspace${where}. Go to the home point first.`
    : `Torque is off: the arm hangs relaxed${where}. Torque on, then go to the home point.`);
  setText("home-point", homeText());
  document.getElementById("first-torque").disabled = s.torque;
  document.getElementById("first-torque").closest("li").classList.toggle("done", s.torque);
  document.getElementById("first-home").disabled = !s.torque;
}

// Every value on the page is from the last status; older than STALE_MS it is greyed.
function checkStale() {
  const stale = lastStatusAt === null || performance.now() - lastStatusAt > STALE_MS;
  document.body.classList.toggle("stale", stale);
}

function servoRow(j, i, torque) {
  const errors = j.hardware_errors[i] || [];
  // the servo's own Torque Enable where the bus reads it (a shutdown turns it off)
  const read = (j.torque_enabled || [])[i];
  const held = read === true || read === false ? read : torque;
  const errorCell = errors.length
    ? `<td class="bad">${errors.map(escape).join(", ")}</td>`
    : `<td class="ok">none</td>`;
  const reboot = errors.length
    ? `<button type="button" data-reboot="${j.servo_ids[i]}">Reboot</button>`
    : held ? "torque on" : "relaxed";
  return `<tr><th scope="row">${j.servo_ids[i]}</th><td>${deg(j.position_rad[i])}</td>` +
    `<td>${deg(j.commanded_rad[i])}</td><td>${deg(j.velocity_rad_s[i], 0)}</td>` +
    `<td>${fixed(j.current_a[i], 3)}</td><td>${fixed(j.pwm[i] == null ? null : 100 * j.pwm[i], 0)}</td>` +
    `<td>${fixed(j.voltage_v[i], 1)}</td>` +
    `<td>${fixed(j.temperature_c[i], 0)}</td>${errorCell}<td>${reboot}</td></tr>`;
}

// The wrist's servo (status.wrist_servo: the fourth on the bus) as a row like the legs':
// phi as read and as commanded in the angle columns.
function wristRow(w, torque) {
  const one = (name) => [w[name]];
  const j = {
    servo_ids: [w.servo_id], position_rad: one("position_rad"), commanded_rad: one("commanded_rad"),
    velocity_rad_s: one("velocity_rad_s"), current_a: one("current_a"), pwm: one("pwm"),
    voltage_v: one("voltage_v"), temperature_c: one("temperature_c"),
    hardware_errors: [w.hardware_errors], torque_enabled: [w.torque_enabled],
  };
  return servoRow(j, 0, torque).replace(`<th scope="row">${w.servo_id}</th>`,
    `<th scope="row" title="the wrist's servo: its angle is φ">${w.servo_id} <span class="muted">wrist</span></th>`);
}

function renderServos(s) {
  const j = s.joints;
  const legs = j.servo_ids.map((_, i) => servoRow(j, i, s.torque).replace(
    `<th scope="row">${j.servo_ids[i]}</th>`, `<th scope="row" title="joint ${i + 1}">${j.servo_ids[i]}</th>`));
  const html = legs.join("") + (s.wrist_servo ? wristRow(s.wrist_servo, s.torque) : "");
  const body = document.getElementById("servo-rows");
  if (body.innerHTML !== html) body.innerHTML = html;
}

export function escape(text) {
  return String(text).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
}

async function poll() {
  const askedAt = performance.now();
  try {
    const s = await get("/api/status");
    state.status = s;
    lastStatusAt = performance.now();
    noteRoundTrip(lastStatusAt - askedAt);
    checkStale();
    if (!state.online) setOnline(true);
    else updateConnection(); // the link fact follows the round trip
    renderHeader(s);
    renderFaults(s);
    renderPosition(s);
    renderServos(s);
    renderFirstSteps(s);
    controlStatus(s);
    toastStatus(s, askedAt);
    state.listeners.forEach((fn) => fn(s));
  } catch (err) {
    setOnline(false, err.message || "no answer");
  }
  // the server answers but its robot is offline: asked again soon, the banner goes at once
  const robotOffline = !state.online && state.why.startsWith("robot offline");
  setTimeout(poll, state.online ? POLL_MS : robotOffline ? 500 : 1000);
}

export function startStatus() {
  // A servo in error is rebooted by the reset, which reboots every servo reporting errors.
  document.getElementById("servo-rows").addEventListener("click", (event) => {
    const id = event.target.dataset.reboot;
    if (id) command("/api/reset").catch(showError);
  });
  document.getElementById("first-torque").addEventListener("click", () =>
    command("/api/torque", { enabled: true }).catch(showError));
  document.getElementById("first-home").addEventListener("click", goHome);
  setInterval(checkStale, 250);
  poll();
}
