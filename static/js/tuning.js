// The tuning panel: the guided procedure of docs/tuning.md from the page. Its steps (move to
// the start point, the step run, the chirp run, the fit, the check of the candidate gains on
// the twin, the report) with the current one marked and a progress bar; start (the joints and
// the target: bandwidth in Hz, phase margin in degrees, overshoot and peak PWM in %),
// abort; the report (each joint's fitted model, the Bode figure inline, the candidates the
// twin check tried with its figures in mm and %, the one chosen and why, the suggested gains
// against those in use) and apply (after a confirmation that says which servo gets which
// gains, and what they miss when they miss the goal) or revert. The run is followed by
// polling GET /api/tuning/{id} while it runs (one request at a time); a reload finds the
// newest run (GET /api/tuning).

import { get, getBlob } from "./api.js";
import { procedureWords } from "./calibration.js";
import { askConfirm, command } from "./control.js";
import { parseDecimal, setText, showMessage } from "./ui.js";

export const STEPS = ["planned", "moving", "step", "chirp", "fitting", "checking", "report"];
const RUNNING = STEPS.slice(0, -1);
const POLL_MS = 500;
// the target's fields: the page's name, unit, limits (the API's, in the page's units) and
// how the page's value becomes the API's
const TARGET = {
  bandwidth_hz: { name: "bandwidth", unit: "Hz", min: 0.1, max: 100, scale: 1 },
  phase_margin_deg: { name: "phase margin", unit: "°", min: 20, max: 85, scale: 1 },
  overshoot_pct: { name: "overshoot", unit: "%", min: 0, max: 50, scale: 1, open: true },
  pwm_fraction: { name: "peak PWM", unit: "% of the limit", min: 5, max: 100, scale: 0.01 },
};
// what the twin check's limits are called on the page, and their units
const LIMIT_WORDS = {
  rmse_xy_m: "tracking error x, y",
  rmse_z_m: "tracking error z",
  at_limit: "PWM at its limit",
  overshoot_pct: "step overshoot",
  rest_m: "error at rest",
  long_overshoot_m: "overshoot after a long move",
  settle_band_m: "settling band",
  settle_s: "settling time after a long move",
};

const view = { run: null, bodeFor: null, said: null };
const panel = { run: () => view.run, said: null }; // window.deltadash.tuning (tests)
let polling = false;
let bodeUrl = null;

const el = (id) => document.getElementById(id);
const mm = (m, digits = 2) => (m === null || m === undefined ? "–" : (m * 1000).toFixed(digits));
const pct = (f, digits = 1) => (f === null || f === undefined ? "–" : (f * 100).toFixed(digits));
const words = (err) => procedureWords(err, "tuning");

function say(text, kind = "") {
  const out = el("tun-message");
  out.textContent = text;
  out.className = `proc-message ${kind}`;
}

// A limit the check found missed, with its value: "error at rest (≤ 0.20 mm)".
export function limitText(name, limits) {
  const v = limits ? limits[name] : undefined;
  const unit = name.endsWith("_m") ? " mm" : name.endsWith("_s") ? " s" : name === "at_limit" || name === "overshoot_pct" ? " %" : "";
  const value = v === undefined ? "" : name.endsWith("_m") ? mm(v) : name === "at_limit" ? pct(v) : Number(v).toFixed(1);
  return `${LIMIT_WORDS[name] || name}${value === "" ? "" : ` (at most ${value}${unit})`}`;
}

// ---- the form ----

// The typed joints and target as the API's body, or the first problem in the page's words.
export function tuningBody(form) {
  const joints = [1, 2, 3].filter((j) => form.elements[`joint${j}`].checked);
  let error = joints.length ? null : "joints: choose at least one joint";
  const target = {};
  for (const [key, f] of Object.entries(TARGET)) {
    const input = form.elements[key];
    const parsed = parseDecimal(input.value);
    let problem = parsed.error ? `${f.name}: ${parsed.error}` : null;
    if (!problem) {
      const v = parsed.value;
      const below = f.open ? v <= f.min : v < f.min;
      if (below || v > f.max) {
        const range = f.open ? `above ${f.min} and at most ${f.max}` : `${f.min} to ${f.max}`;
        problem = `${f.name}: ${v} ${f.unit} is outside ${range} ${f.unit}`;
      }
      target[key] = v * f.scale;
    }
    input.setAttribute("aria-invalid", problem ? "true" : "false");
    error = error || problem;
  }
  target.feedforward = form.elements.feedforward.checked;
  return error ? { error } : { joints, target };
}

async function start(event) {
  event.preventDefault();
  const body = tuningBody(el("tun-form"));
  if (body.error) {
    say(`Not started: ${body.error}`, "bad");
    showMessage(`Not started: ${body.error}`, "error");
    return;
  }
  el("tun-start").disabled = true;
  try {
    const { run_id: id } = await command("/api/tuning/run", body);
    showMessage(`Tuning ${id} started: the arm moves to the start point`);
    await follow(id);
  } catch (err) {
    say(`Not started: ${words(err)}`, "bad");
    showMessage(`Not started: ${words(err)}`, "error", { detail: err.message });
  } finally {
    render();
  }
}

async function abort() {
  const run = view.run;
  if (!run || !RUNNING.includes(run.state)) return;
  try {
    view.run = await command(`/api/tuning/${run.run_id}/abort`);
    showMessage(`Tuning ${run.run_id} aborted: the arm holds where it is`);
  } catch (err) {
    showMessage(words(err), "error", { detail: err.message });
  }
  render();
}

// ---- apply / revert ----

const gainsText = (g) => `P ${g.p}, I ${g.i}, D ${g.d}${g.ff1 || g.ff2 ? `, FF1 ${g.ff1}, FF2 ${g.ff2}` : ""}`;

// What an apply changes, in the page's words (the confirmation says it).
export function applyText(run) {
  const servos = Object.entries(run.suggested).map(([sid, g]) => `servo ${sid}: ${gainsText(g)}`).join("; ");
  let text = `Apply tuning ${run.run_id}? These gains go to the servos from now on: ${servos}. ` +
    "The gains in use now are kept for Revert; written to the config file if the server runs from one.";
  const checked = run.checked;
  if (checked && !checked.met_goal) {
    const chosen = checked.candidates[checked.chosen - 1];
    const missed = chosen.failed.map((name) => limitText(name, checked.limits)).join(", ");
    text += ` On the twin they MISS the goal: ${missed}. Apply them anyway?`;
  }
  return text;
}

async function apply() {
  const run = view.run;
  if (!run || run.state !== "done") return;
  const text = applyText(run);
  panel.said = text;
  const missed = run.checked && !run.checked.met_goal;
  if (!(await askConfirm(text, missed ? "Apply anyway" : "Apply"))) {
    say("not applied: the servos keep their gains", "muted");
    return;
  }
  try {
    const applied = await command(`/api/tuning/${run.run_id}/apply`, missed ? { confirm_missed: true } : undefined);
    panel.applied = applied;
    const where = applied.config_written ? ` and written to ${applied.config_written}` : "";
    showMessage(`Tuning ${run.run_id} applied${where}`);
    say(`applied: ${Object.entries(applied.gains).map(([sid, g]) => `servo ${sid} ${gainsText(g)}`).join("; ")}`, "ok");
    view.run = await get(`/api/tuning/${run.run_id}`);
  } catch (err) {
    say(`Not applied: ${words(err)}`, "bad");
    showMessage(`Not applied: ${words(err)}`, "error", { detail: err.message });
  }
  render();
}

async function revert() {
  if (!(await askConfirm("Revert: the gains in use before the last apply or write go back to the servos (and the config file). Nothing moves.", "Revert"))) return;
  try {
    const back = await command("/api/tuning/revert");
    panel.reverted = back;
    showMessage("Gains reverted");
    say(`reverted: ${Object.entries(back.gains).map(([sid, g]) => `servo ${sid} ${gainsText(g)}`).join("; ")}`, "ok");
  } catch (err) {
    say(`Not reverted: ${words(err)}`, "bad");
    showMessage(`Not reverted: ${words(err)}`, "error", { detail: err.message });
  }
}

// ---- following the run ----

async function follow(id) {
  view.run = await get(`/api/tuning/${id}`);
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
        const body = await get(`/api/tuning/${shown}`);
        if (view.run.run_id === shown) view.run = body; // not one started meanwhile
      } catch (err) {
        say(`cannot read the run: ${words(err)}`, "bad");
      }
      render();
    }
  } finally {
    polling = false;
  }
  const r = view.run;
  if (followed && r && r.state !== "aborted") {
    const said = r.state === "done" ? "done: see its report below" : `${r.state}${r.error ? `: ${words({ message: r.error })}` : ""}`;
    showMessage(`Tuning ${r.run_id} ${said}`, r.state === "failed" ? "error" : "info");
  }
}

export function stepOf(run) {
  if (!run) return -1;
  const k = STEPS.indexOf(run.state);
  return k >= 0 ? k : STEPS.length - 1;
}

function renderSteps(run) {
  const at = stepOf(run);
  const ended = run && !RUNNING.includes(run.state);
  const good = run && ["done", "applied"].includes(run.state);
  el("tun-steps").querySelectorAll("li").forEach((li, k) => {
    const current = k === at;
    li.className = k < at || (ended && current && good) ? "done" : current ? "current" : "";
    if (current) li.setAttribute("aria-current", "step"); else li.removeAttribute("aria-current");
  });
  // an ended run that did not finish shows how far it got: the steps its run ids reached
  el("tun-progress").value = !run ? 0 : good ? 1 : RUNNING.includes(run.state) ? at / (STEPS.length - 1) : el("tun-progress").value;
  setText("tun-progress-text", !run ? "no run yet" : `${run.run_id}: ${run.state}, joints ${run.joints.join(", ")}`);
}

function modelRows(run) {
  return Object.entries(run.model).map(([sid, m]) => {
    const p = run.predicted[sid];
    const now = p && p.current ? p.current.bandwidth_hz : null;
    const then = p && p.suggested ? p.suggested.bandwidth_hz : null;
    const hz = (v) => (v === null || v === undefined ? "–" : v.toFixed(1));
    return `<tr><th scope="row">servo ${sid} (joint ${m.joint})</th><td>${hz(m.bandwidth_hz)}</td>` +
      `<td>${m.zeta.toFixed(2)}</td><td>${(m.delay_s * 1000).toFixed(1)}</td>` +
      `<td>${((m.rmse_rad * 180) / Math.PI).toFixed(3)}</td><td>${hz(now)} → ${hz(then)}</td></tr>`;
  }).join("");
}

// The API's sentence with the limits' names in words ("rmse_xy_m" -> "tracking error x, y").
export function inWords(text) {
  return Object.entries(LIMIT_WORDS).reduce((t, [name, said]) => t.replaceAll(name, said), text);
}

// A candidate's gains for the servos tuned (the others keep theirs): one set when they are
// the same, else each servo's.
export function candidateGains(run, gains) {
  const tuned = Object.keys(run.suggested);
  const sets = tuned.map((sid) => gainsText(gains[sid]));
  return new Set(sets).size === 1 ? sets[0] : tuned.map((sid, k) => `servo ${sid}: ${sets[k]}`).join("; ");
}

function candidateRows(run) {
  const c = run.checked;
  const rmse = (t) => t.rmse_m.map((v) => mm(v)).join(" / ");
  return c.candidates.map((k) => {
    const gains = candidateGains(run, k.gains);
    const long = `${mm(Math.max(...k.long_move.overshoot_m))} / ${Math.max(...k.long_move.settle_s).toFixed(2)}`;
    const chosen = k.candidate === c.chosen;
    const misses = k.failed.length ? k.failed.map((n) => LIMIT_WORDS[n] || n).join(", ") : "none";
    return `<tr class="${chosen ? "chosen" : ""}" data-candidate="${k.candidate}">` +
      `<th scope="row">${chosen ? "▶ " : ""}${k.candidate}</th><td>${gains}</td>` +
      `<td class="num">${rmse(k.plain)}</td><td class="num">${rmse(k.lead)}</td>` +
      `<td class="num">${pct(Math.max(k.plain.at_limit, k.lead.at_limit))}</td><td class="num">${k.overshoot_pct.toFixed(1)}</td>` +
      `<td class="num">${mm(Math.max(...k.rest_m))}</td><td class="num">${long}</td><td>${k.passes ? "passes" : `misses: ${misses}`}</td></tr>`;
  }).join("");
}

function renderReport(run) {
  const box = el("tun-report");
  if (!run) { box.hidden = true; return; }
  box.hidden = false;
  const c = run.checked;
  let verdict;
  if (run.state === "done" || run.state === "applied") {
    verdict = c && c.met_goal ? "The suggested gains meet the goal on the twin." : "The suggested gains do NOT meet the goal on the twin (the closest set is offered).";
    if (run.state === "applied") verdict += " Applied: the servos use them.";
  } else if (RUNNING.includes(run.state)) {
    verdict = `${run.state}…`;
  } else if (run.state === "aborted") {
    verdict = "The run was aborted by the operator: nothing is suggested.";
  } else {
    verdict = `The run ${run.state}${run.error ? `: ${words({ message: run.error })}` : ""}`;
  }
  setText("tun-verdict", verdict);
  el("tun-verdict").className = `proc-verdict ${c && c.met_goal ? "ok" : ["failed"].includes(run.state) || (c && !c.met_goal) ? "bad" : "muted"}`;
  el("tun-models").innerHTML = modelRows(run);
  el("tun-candidates").innerHTML = c ? candidateRows(run) : "";
  el("tun-candidates-part").hidden = !c;
  if (c) {
    setText("tun-reason", inWords(c.reason));
    setText("tun-goal", `Goal on the twin: ${Object.keys(c.limits).map((n) => limitText(n, c.limits)).join(", ")}; loop lead ${(c.lead_s * 1000).toFixed(0)} ms, gravity compensation ${c.gravity_compensation ? "on" : "off"}, ${c.seconds.toFixed(0)} s of sinusoid.`);
  }
  el("tun-report").dataset.run = run.run_id;
  el("tun-apply").disabled = run.state !== "done";
  showBode(run);
}

async function showBode(run) {
  const img = el("tun-bode");
  if (!run.files.includes("bode.png")) {
    img.hidden = true;
    return;
  }
  if (view.bodeFor === run.run_id) return;
  view.bodeFor = run.run_id;
  try {
    const blob = await getBlob(`/api/tuning/${run.run_id}/bode.png`);
    if (bodeUrl) URL.revokeObjectURL(bodeUrl);
    bodeUrl = URL.createObjectURL(blob);
    img.src = bodeUrl;
    img.dataset.run = run.run_id;
    img.hidden = false;
  } catch (err) {
    view.bodeFor = null;
    say(`Bode figure: ${words(err)}`, "bad");
  }
}

function render() {
  const run = view.run;
  const running = Boolean(run && RUNNING.includes(run.state));
  el("tun-start").disabled = running;
  el("tun-abort").disabled = !running;
  renderSteps(run);
  renderReport(run);
  if (running) {
    const doing = {
      planned: "starting…", moving: "moving to the start point…", step: "recording the step…",
      chirp: "recording the chirp…", fitting: "fitting each joint's model…",
      checking: "checking the candidate gains on the twin (this takes a minute or more)…",
    };
    say(doing[run.state] || `${run.state}…`, "muted");
  } else if (run && run.run_id !== view.said) { // the run has ended: its verdict says how
    view.said = run.run_id;
    say("", "");
  }
}

// The newest run this server knows (a reload finds the run in progress, or the last report).
async function latest() {
  try {
    const runs = await get("/api/tuning");
    if (runs.length) await follow(runs[0].run_id);
  } catch {
    // the server is not up yet: the panel starts empty
  }
}

function openImage() {
  const img = el("tun-bode");
  const box = document.getElementById("report-box");
  if (!img.src || !box) return;
  document.getElementById("report-img").src = img.src;
  setText("report-title", `Tuning ${img.dataset.run}: measured against fitted`);
  document.getElementById("report-open").href = img.src;
  if (!box.open) box.showModal();
}

export function startTuning() {
  window.deltadash = Object.assign(window.deltadash || {}, { tuning: panel });
  el("tun-form").addEventListener("submit", start);
  el("tun-abort").addEventListener("click", abort);
  el("tun-apply").addEventListener("click", apply);
  el("tun-revert").addEventListener("click", revert);
  el("tun-bode").addEventListener("click", openImage);
  render();
  latest();
}
