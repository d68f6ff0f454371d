// The running program's motion control, as AXIS and Mainsail have it (docs/gcode.md "Pause,
// step and feed override"): Pause / Resume (POST /api/programs/pause, /resume: the tool slows
// along the checked path and stands on it), Step (POST /api/programs/step: to the end of the
// line it is on, and stands there), the feed override slider 10-100 % (PUT /api/programs/feed:
// the program was checked at 100 %, so it only ever slows), the optional stop switch for M1
// (PUT /api/programs/optional-stop), and "run from line" for the next Run (programs.js asks
// runOptions() for it, the slider's feed and the switch). It follows the running program from
// GET /api/runs (its progress: paused, feed_override, program_line, time_left_s): the state,
// the line and the time left.

import { get, request, takeLease } from "./api.js";
import { command } from "./control.js";
import { operatorText, parseDecimal, setText, showError, showMessage } from "./ui.js";

const RUNNING_POLL_MS = 500; // while a program runs: its state and line move on
const IDLE_POLL_MS = 3000;
let playing = null; // { id, progress } of the program run going on (GET /api/runs)
let polling = false;
let polledAt = -Infinity;
let sending = false; // a command is on its way: the buttons wait for its answer

const el = (id) => document.getElementById(id);
const feedPercent = () => Number(el("pc-feed").value);

// "1:05" from seconds; "–" when unknown
function clock(seconds) {
  if (seconds === null || seconds === undefined || !Number.isFinite(seconds)) return "–";
  const s = Math.max(0, Math.round(seconds));
  const h = Math.floor(s / 3600);
  const m = Math.floor((s % 3600) / 60);
  const ss = String(s % 60).padStart(2, "0");
  return h ? `${h}:${String(m).padStart(2, "0")}:${ss}` : `${m}:${ss}`;
}

// What a Run starts with: the slider's feed, the optional stop, the line to start from.
// null (and the reason said beside the field) when the line typed is not a line number:
// nothing is sent then.
export function runOptions() {
  const options = { feed_override: feedPercent() / 100, optional_stop: el("pc-optional").checked };
  const typed = el("pc-from").value.trim();
  el("pc-from").removeAttribute("aria-invalid");
  if (!typed) return options;
  const parsed = parseDecimal(typed);
  if (parsed.error || !Number.isInteger(parsed.value) || parsed.value < 1) {
    el("pc-from").setAttribute("aria-invalid", "true");
    const why = parsed.error ? `run from line ${parsed.error}` : `run from line: "${typed}" is not a line number (1, 2, 3 …)`;
    setText("pc-state", `not started: ${why}`);
    showMessage(`Not started: ${why}`, "error");
    return null;
  }
  return { ...options, start_line: parsed.value };
}

const isStanding = (p) => Boolean(p && p.paused && p.paused !== "pausing");

function render() {
  const p = playing && playing.progress;
  const state = el("pc-state");
  const pause = el("pc-pause");
  pause.disabled = !playing || sending;
  el("pc-step").disabled = !playing || sending;
  const standing = isStanding(p);
  pause.textContent = standing || (p && p.paused === "pausing") ? "Resume" : "Pause";
  pause.classList.toggle("primary", standing);
  pause.title = standing ? "go on at the feed override" : "slow along the path and stand on it";
  let text = "no program running";
  if (playing && p) {
    const line = Number.isInteger(p.program_line) ? `line ${p.program_line}` : p.phase === "approach" ? "approach to its start" : "starting";
    const feed = Number.isFinite(p.feed_override) ? ` at ${Math.round(p.feed_override * 100)} % feed` : "";
    if (standing) text = `paused: ${p.paused}`;
    else if (p.paused === "pausing") text = `pausing on ${line}`;
    else if (Number.isInteger(p.stop_line)) text = `stepping: ${line}, stops at the end of line ${p.stop_line}`;
    else text = `running ${line}${feed}`;
  } else if (playing) {
    text = "running";
  }
  setText("pc-state", text);
  state.classList.toggle("paused", standing || Boolean(p && p.paused === "pausing"));
  state.dataset.paused = standing ? "true" : "false";
  state.dataset.line = p && Number.isInteger(p.program_line) ? String(p.program_line) : "";
  const left = p && Number.isFinite(p.time_left_s) ? p.time_left_s : null;
  setText("pc-left", playing && left !== null ? `time left ${clock(left)}${standing ? " after Resume" : ""}` : "");
  el("pc-left").dataset.seconds = left === null ? "" : String(left);
}

async function poll() {
  if (polling) return;
  polling = true;
  polledAt = performance.now();
  try {
    const runs = await get("/api/runs");
    const now = runs.find((r) => r.state === "running" && r.kind === "program");
    playing = now ? { id: now.run_id, progress: now.progress || null } : null;
    if (now && now.progress && Number.isFinite(now.progress.feed_override) && !sending
        && document.activeElement !== el("pc-feed")) {
      el("pc-feed").value = String(Math.round(now.progress.feed_override * 100));
      showFeed();
    }
    if (now && now.progress && typeof now.progress.optional_stop === "boolean"
        && document.activeElement !== el("pc-optional")) {
      el("pc-optional").checked = now.progress.optional_stop;
    }
    render();
  } catch {
    // the status poll shows the connection banner; keep what is shown
  } finally {
    polling = false;
  }
}

// A PUT that needs the lease: this tab takes it once when the server does not know ours.
async function putControl(path, body) {
  try {
    return await request("PUT", path, body);
  } catch (err) {
    if (err.status !== 409 || !err.message.includes("/api/lease")) throw err;
    await takeLease(false);
    return request("PUT", path, body);
  }
}

// Send one command; the answer is the run's new state (shown at once, polled after).
async function send(make) {
  if (sending) return;
  sending = true;
  render();
  try {
    const answer = await make();
    if (playing && answer && answer.run_id === playing.id) {
      playing.progress = { ...(playing.progress || {}), ...answer };
    }
  } catch (err) {
    const { text } = operatorText(err);
    setText("pc-state", `not done: ${text}`);
    showError(err);
  } finally {
    sending = false;
    render();
    poll();
  }
}

function pauseOrResume() {
  const p = playing && playing.progress;
  const resume = isStanding(p) || Boolean(p && p.paused === "pausing");
  send(() => command(resume ? "/api/programs/resume" : "/api/programs/pause"));
}

function step() {
  send(() => command("/api/programs/step"));
}

function showFeed() {
  setText("pc-feed-out", `${feedPercent()} %`);
  el("pc-feed").setAttribute("aria-valuetext", `${feedPercent()} percent of the programmed feed`);
}

function feedChanged() {
  showFeed();
  if (playing) send(() => putControl("/api/programs/feed", { override: feedPercent() / 100 }));
}

function optionalChanged() {
  if (playing) send(() => putControl("/api/programs/optional-stop", { on: el("pc-optional").checked }));
}

export function startProgramControl() {
  if (!el("pc-pause")) return;
  el("pc-pause").addEventListener("click", pauseOrResume);
  el("pc-step").addEventListener("click", step);
  el("pc-feed").addEventListener("input", showFeed);
  el("pc-feed").addEventListener("change", feedChanged);
  el("pc-optional").addEventListener("change", optionalChanged);
  el("pc-from").addEventListener("input", () => el("pc-from").removeAttribute("aria-invalid"));
  showFeed();
  render();
  poll();
  setInterval(() => {
    const due = playing ? RUNNING_POLL_MS : IDLE_POLL_MS;
    if (performance.now() - polledAt >= due - 50) poll();
  }, RUNNING_POLL_MS);
}
