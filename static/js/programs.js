// The program panel: paste or open a G-code program, Check it (POST /api/programs/check: the
// whole path verified in joint space on the virtual robot, nothing moves), see its violations
// by line, each line's first cause with the others folded under it (a click marks the line in
// the text), Run it once a check of this very text passed
// (POST /api/programs/run), Abort it (POST /api/runs/{id}/abort). While a program runs, the
// line being executed (its progress "program_line" in GET /api/runs) is highlighted.
//
// Editing the text after a check invalidates the check: Run waits for a new one. The text box
// is a plain textarea (Space types a space there; Esc still e-stops: control.js's onKey).

import { get, post, fixed } from "./api.js";
import { command } from "./control.js";
import { escape } from "./status.js";
import { metresToMm, operatorText, setText, showError, showMessage } from "./ui.js";
import { showProgram } from "./workspace2d.js";

const RUNS_POLL_MS = 1000; // while a program runs (its line moves on); else every IDLE_POLL_MS
const IDLE_POLL_MS = 3000;
const MAX_FILE_BYTES = 4 * 1024 * 1024; // [bytes] the server refuses more than 100,000 lines anyway
let checked = null; // { text, report } of the last check answered (report.ok: it passes)
let running = null; // { id, line } of the program run going on (from GET /api/runs)
let marked = null; // the program line marked by a click on a violation (or a 422), 1-based
let checking = false;
let polling = false;
let polledAt = -Infinity; // performance.now() of the last GET /api/runs

const textBox = () => document.getElementById("prog-text");
const mmPoint = (p) => `(${p.map((v) => (v * 1000).toFixed(1)).join(", ")}) mm`;

// ---- the text, its line numbers and the two bands (marked line, running line) ----

function renderGutter() {
  const count = textBox().value.split("\n").length;
  const gutter = document.getElementById("prog-gutter");
  if (gutter.childElementCount !== count) {
    gutter.innerHTML = Array.from({ length: count }, (_, i) => `<span data-line="${i + 1}">${i + 1}</span>`).join("");
  }
  paintLines();
}

function lineHeightPx() {
  return parseFloat(getComputedStyle(textBox()).lineHeight) || 18;
}

// Bands and gutter numbers follow the text's scroll; one class per kind on the gutter.
function paintLines() {
  const box = textBox();
  const gutter = document.getElementById("prog-gutter");
  gutter.scrollTop = box.scrollTop;
  const top = parseFloat(getComputedStyle(box).paddingTop) || 0;
  const place = (id, line) => {
    const band = document.getElementById(id);
    band.hidden = !line;
    if (line) band.style.top = `${top + (line - 1) * lineHeightPx() - box.scrollTop}px`;
  };
  place("prog-mark", marked);
  place("prog-running", running && running.line);
  for (const [cls, line] of [["marked", marked], ["running", running && running.line]]) {
    gutter.querySelectorAll(`span.${cls}`).forEach((s) => { if (Number(s.dataset.line) !== line) s.classList.remove(cls); });
    if (line) gutter.querySelector(`span[data-line="${line}"]`)?.classList.add(cls);
  }
  box.dataset.markedLine = marked ? String(marked) : "";
  box.dataset.runningLine = running && running.line ? String(running.line) : "";
}

// Scroll the text so ``line`` shows (a third down the box), without taking the focus.
function reveal(line) {
  const box = textBox();
  const lh = lineHeightPx();
  const y = (line - 1) * lh;
  if (y < box.scrollTop || y > box.scrollTop + box.clientHeight - 2 * lh) {
    box.scrollTop = Math.max(0, y - box.clientHeight / 3);
  }
}

// Mark ``line`` (1-based) in the text: its band and number, its text selected.
export function markLine(line) {
  marked = line;
  const box = textBox();
  const lines = box.value.split("\n");
  if (line && line <= lines.length) {
    const start = lines.slice(0, line - 1).reduce((n, l) => n + l.length + 1, 0);
    box.setSelectionRange(start, start + lines[line - 1].length);
    reveal(line);
  }
  document.querySelectorAll("#prog-violation-rows tr").forEach((tr) =>
    tr.classList.toggle("marked", Number(tr.dataset.line) === line));
  paintLines();
}

// ---- the check's report ----

// ``answer``: the text is a check's answer (counted in data-answers: a test, or a reader,
// tells a fresh answer from the last one when both read the same)
function setResult(text, kind = "", answer = false) {
  const out = document.getElementById("prog-result");
  out.textContent = text;
  out.className = `preview ${kind}`;
  if (answer) out.dataset.answers = String(Number(out.dataset.answers || 0) + 1);
}

function runnable() {
  return Boolean(checked && checked.report && checked.report.ok && checked.text === textBox().value && !running);
}

function updateButtons() {
  const run = document.getElementById("prog-run");
  run.disabled = !runnable();
  run.title = run.disabled ? (running ? "a program is running" : "check the program first (Run needs a passing check of this text)") : "";
  document.getElementById("prog-abort").disabled = !running;
  document.getElementById("prog-check").disabled = checking;
}

function figures(report) {
  const rows = [
    ["duration", `${fixed(report.duration_s, 2)} s`],
    ["path length", `${fixed(report.length_m * 1000, 1)} mm`],
    ["peak joint speed", report.peak_joint_speed_rad_s === null ? "–" :
      `${fixed(report.peak_joint_speed_rad_s, 2)} rad/s (${fixed(report.peak_joint_speed_rad_s * 180 / Math.PI, 0)}°/s)`],
    ["worst torque ratio", report.worst_torque_ratio === null ? "–" : `${fixed(report.worst_torque_ratio, 2)} of the servo's`],
    ["worst 1/cond(J)", report.worst_dexterity === null ? "–" : fixed(report.worst_dexterity, 3)],
    ["lines, samples", `${report.lines}, ${report.samples}`],
  ];
  const notes = (report.notes || []).map((n) => ["note", n]);
  return [...rows, ...notes].map(([k, v]) => `<dt>${escape(k)}</dt><dd>${escape(v)}</dd>`).join("");
}

// The violations by move, as the server lists them (each line's first cause, then the others
// with folded_under its index): one row per first cause, with a "+N more" button that unfolds
// the others (rows hidden until then). A violation without folded_under is a first cause.
const isFolded = (v) => Number.isInteger(v.folded_under);

function violationRows(violations) {
  const more = new Map(); // index of a first cause -> how many are folded under it
  for (const v of violations) if (isFolded(v)) more.set(v.folded_under, (more.get(v.folded_under) || 0) + 1);
  return violations.map((v, k) => {
    const folded = isFolded(v);
    const count = more.get(k) || 0;
    const fold = count ? ` <button type="button" class="prog-more" data-more="${k}" aria-expanded="false"` +
      ` title="the ${count} other finding${count === 1 ? "" : "s"} of line ${v.line} (after its first cause)">+${count} more</button>` : "";
    return `<tr data-line="${v.line}" data-index="${k}"${folded ? ` data-folded-under="${v.folded_under}" class="folded" hidden` : ""}` +
      ` tabindex="0" title="click: mark line ${v.line} in the program">` +
      `<td>${v.line}</td><td>${escape(v.kind)}</td>` +
      `<td>${folded ? "↳ " : ""}${escape(metresToMm(v.message))}${Array.isArray(v.point_m) ? ` <span class="muted">at ${mmPoint(v.point_m)}</span>` : ""}${fold}</td>` +
      `<td class="num">${fixed(v.t_s, 3)}</td></tr>`;
  }).join("");
}

// Show or hide the violations folded under the first cause of ``button`` (its "+N more").
function toggleFold(button) {
  const open = button.getAttribute("aria-expanded") !== "true";
  document.querySelectorAll(`#prog-violation-rows tr[data-folded-under="${button.dataset.more}"]`)
    .forEach((tr) => { tr.hidden = !open; });
  button.setAttribute("aria-expanded", String(open));
  const count = button.textContent.match(/\d+/)[0];
  button.textContent = open ? `fold ${count}` : `+${count} more`;
}

function showViolations(violations) {
  const table = document.getElementById("prog-violations");
  document.getElementById("prog-violation-rows").innerHTML = violationRows(violations || []);
  table.hidden = !violations || !violations.length;
}

// A report (the check's, or a refused run's): result line, figures, violations, the drawing.
function showReport(report, text) {
  checked = { text, report };
  const n = report.violations.length;
  const lines = new Set(report.violations.map((v) => v.line)).size;
  const folded = report.violations.filter(isFolded).length;
  setResult(report.ok ? `passes: ${fixed(report.duration_s, 2)} s, path ${fixed(report.length_m * 1000, 1)} mm` :
    `fails: ${n} violation${n === 1 ? "" : "s"} on ${lines} line${lines === 1 ? "" : "s"}` +
    (folded ? ` (the first cause of each shown, ${folded} more folded under them)` : ""), report.ok ? "ok" : "bad", true);
  document.getElementById("prog-figures").innerHTML = figures(report);
  showViolations(report.violations);
  markLine(null);
  showProgram(report);
  updateButtons();
}

// A program that cannot be read (422 {detail, line, word}): its line marked and named.
function showUnreadable(body, text) {
  checked = { text, report: null };
  const where = [body.line ? `line ${body.line}` : "", body.word ? `word "${body.word}"` : ""].filter(Boolean).join(", ");
  setResult(`cannot be read${where ? ` (${where})` : ""}: ${body.detail}`, "bad", true);
  document.getElementById("prog-figures").innerHTML = "";
  showViolations([]);
  markLine(body.line || null);
  showProgram(null);
  updateButtons();
}

async function check() {
  const text = textBox().value;
  if (!text.trim()) {
    setResult("nothing to check: paste or open a program", "bad");
    return;
  }
  checking = true;
  updateButtons();
  setResult("checking… (every loop sample of the path, on the virtual robot)");
  try {
    showReport(await post("/api/programs/check", { gcode: text }), text);
  } catch (err) {
    if (err.status === 422 && err.body && "line" in err.body) showUnreadable(err.body, text);
    else setResult(`not checked: ${operatorText(err).text}`, "bad", true);
  } finally {
    checking = false;
    if (checked && checked.text !== textBox().value) edited(); // typed on meanwhile
    updateButtons();
  }
}

// The text changed: the check no longer speaks for it.
function edited() {
  renderGutter();
  if (checked && checked.text !== textBox().value) {
    if (checked.report) setResult("changed since the check: press Check again (Run waits for it)", "");
    checked = null;
    markLine(null);
  }
  updateButtons();
}

// ---- run and abort ----

// The check's violations in a refused run's 422, wherever the server put them (every
// programs 422 has a violations list: empty for an unreadable program, {field, reason}
// for a refused body; only the check's, with a kind, make a refused run).
function refusedReport(body) {
  if (!body) return null;
  for (const r of [body, body.detail, body.report, body.detail && body.detail.report]) {
    if (r && typeof r === "object" && Array.isArray(r.violations)
        && r.violations.some((v) => v && typeof v === "object" && "kind" in v)) return r;
  }
  return null;
}

async function run() {
  if (!runnable()) return;
  const text = checked.text;
  const body = { gcode: text, feedforward: document.getElementById("prog-ff").checked };
  try {
    const answer = await command("/api/programs/run", body);
    running = { id: answer.run_id, line: null };
    setText("prog-state", `run ${answer.run_id} started`);
    showMessage(`Program run ${answer.run_id} started`);
    updateButtons();
    pollRuns();
  } catch (err) {
    const refused = err.status === 422 ? refusedReport(err.body) : null;
    if (refused && "duration_s" in refused) {
      showReport(refused, text);
      setResult(`not started: ${document.getElementById("prog-result").textContent}`, "bad");
    } else if (refused) {
      checked = null;
      showViolations(refused.violations);
      setResult(`not started: ${refused.violations.length} violation(s) from where the robot is now`, "bad");
      updateButtons();
    } else if (err.status === 422 && err.body && "line" in err.body) {
      showUnreadable(err.body, text);
    } else {
      showError(err);
    }
  }
}

function abort() {
  if (!running) return;
  command(`/api/runs/${running.id}/abort`).then(pollRuns).catch(showError);
}

// A program run started here, elsewhere (CLI, another tab) or before a reload: followed
// from the server's record, with the line it is on.
async function pollRuns() {
  if (polling) return;
  polling = true;
  polledAt = performance.now();
  try {
    const runs = await get("/api/runs");
    const now = runs.find((r) => r.state === "running" && r.kind === "program");
    if (now) {
      const line = now.progress && Number.isInteger(now.progress.program_line) ? now.progress.program_line : null;
      if (!running || running.id !== now.run_id || running.line !== line) {
        running = { id: now.run_id, line };
        if (line) reveal(line);
      }
      setText("prog-state", `run ${now.run_id}: ${line ? `line ${line}` : "starting"}`);
    } else if (running) {
      const ended = runs.find((r) => r.run_id === running.id);
      setText("prog-state", `run ${running.id}: ${ended ? ended.state : "ended"}`);
      running = null;
    }
    paintLines();
    updateButtons();
  } catch {
    // the status poll shows the connection banner; keep what is shown
  } finally {
    polling = false;
  }
}

async function openFile(event) {
  const file = event.target.files && event.target.files[0];
  if (!file) return;
  if (file.size > MAX_FILE_BYTES) {
    showMessage(`${file.name} is too large for a program (${(file.size / 1048576).toFixed(1)} MB)`, "error");
    return;
  }
  textBox().value = await file.text();
  setText("prog-file-name", file.name);
  textBox().scrollTop = 0;
  edited();
  event.target.value = ""; // the same file again is a change too
}

function onViolationClick(event) {
  const button = event.target.closest("button[data-more]");
  if (button) toggleFold(button); // and the line is marked, as a click on its row does
  const row = event.target.closest("tr[data-line]");
  if (row) markLine(Number(row.dataset.line));
}

export function startPrograms() {
  const box = textBox();
  if (!box) return;
  box.addEventListener("input", edited);
  box.addEventListener("scroll", paintLines);
  document.getElementById("prog-check").addEventListener("click", check);
  document.getElementById("prog-run").addEventListener("click", run);
  document.getElementById("prog-abort").addEventListener("click", abort);
  document.getElementById("prog-file").addEventListener("change", openFile);
  const rows = document.getElementById("prog-violation-rows");
  rows.addEventListener("click", onViolationClick);
  // (Enter on a "+N more" button is its own click)
  rows.addEventListener("keydown", (event) => { if (event.key === "Enter" && !event.target.closest("button")) onViolationClick(event); });
  renderGutter();
  updateButtons();
  pollRuns();
  setInterval(() => { if (running || performance.now() - polledAt >= IDLE_POLL_MS) pollRuns(); }, RUNS_POLL_MS);
}
