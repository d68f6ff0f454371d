// The program panel: paste or open a G-code program, Check it (POST /api/programs/check: the
// whole path verified in joint space on the virtual robot, nothing moves), see its violations
// by line, each line's first cause with the others folded under it (a click marks the line in
// the text), Run it once a check of this very text passed
// (POST /api/programs/run), Abort it (POST /api/runs/{id}/abort). While a program runs, the
// line being executed (its progress "program_line" in GET /api/runs) is highlighted.
//
// Editing the text after a check invalidates the check: Run waits for a new one. The text box
// is a plain textarea (Space types a space there; Esc still e-stops: control.js's onKey).
//
// The work offset (G54, mm) goes with every check, dry run and run (work_offset_m): the
// config's (GET /api/programs/defaults) until a program states its own in a comment
// ("G54 at 0, 0, -0.28 m" or "--work-offset 0 0 -280", as examples/pick_and_place.ngc
// does): opening such a file (or a library entry) sets it, and typed text that states one
// offers it (a button). The file name shows only while the text is the file's. Every
// program sent is kept by the server (GET /api/programs/library) and can be reopened.
// Dry run (POST /api/programs/dry-run): the program played on the twin, the predicted
// error per line in a table, the worst line marked in the text.

import { get, post, fixed } from "./api.js";
import { command } from "./control.js";
import { runOptions } from "./programcontrol.js";
import { escape } from "./status.js";
import { metresToMm, operatorText, parseDecimal, setText, showError, showMessage } from "./ui.js";
import { showProgram } from "./workspace2d.js";

const RUNS_POLL_MS = 1000; // while a program runs (its line moves on); else every IDLE_POLL_MS
const IDLE_POLL_MS = 3000;
const LIBRARY_POLL_MS = 30000; // the program library's list, besides after each send
const MAX_FILE_BYTES = 4 * 1024 * 1024; // [bytes] the server refuses more than 100,000 lines anyway
let checked = null; // { text, offset, report } of the last check answered (report.ok: it passes)
let loaded = null; // { name, text } of the file (or library entry) last opened
let configOffsetMm = [0, 0, 0]; // the config's work offset (GET /api/programs/defaults) [mm]
let worst = null; // the dry run's worst line (1-based), marked in the text
let dryText = null; // the text the dry run shown is of
let dryBusy = false;
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
  place("prog-worst", worst);
  for (const [cls, line] of [["marked", marked], ["running", running && running.line], ["worst", worst]]) {
    gutter.querySelectorAll(`span.${cls}`).forEach((s) => { if (Number(s.dataset.line) !== line) s.classList.remove(cls); });
    if (line) gutter.querySelector(`span[data-line="${line}"]`)?.classList.add(cls);
  }
  box.dataset.markedLine = marked ? String(marked) : "";
  box.dataset.runningLine = running && running.line ? String(running.line) : "";
  box.dataset.worstLine = worst ? String(worst) : "";
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


// ---- the work offset (G54), the file's name, the library ----

const OFFSET_IDS = ["prog-off-x", "prog-off-y", "prog-off-z"];
const NUM = "[+\\-\u2212]?(?:\\d+(?:[.,]\\d*)?|[.,]\\d+)";
const num = (t) => Number(String(t).replace("\u2212", "-").replace(",", "."));
const mmText = (mm) => mm.map((v) => String(Number(v.toFixed(3)))).join(", ");

// The work offset a program states in its comments, {mm, line} or null: "G54 at X, Y, Z m"
// (or mm) and "--work-offset X Y Z" (the CLI's option, in mm), as examples/ write it.
export function statedOffset(text) {
  const forms = [
    [new RegExp(`G54\\s+at\\s+(${NUM})\\s*,\\s*(${NUM})\\s*,\\s*(${NUM})\\s*(mm|m)\\b`, "i"), (m) => (m[4].toLowerCase() === "m" ? 1000 : 1)],
    [new RegExp(`--work-offset\\s+(${NUM})\\s+(${NUM})\\s+(${NUM})`), () => 1],
  ];
  const lines = text.split("\n");
  for (let k = 0; k < lines.length; k += 1) {
    const comments = [...lines[k].matchAll(/\(([^)]*)\)|;(.*)$/g)].map((c) => c[1] ?? c[2] ?? "");
    for (const comment of comments) {
      for (const [re, scale] of forms) {
        const m = comment.match(re);
        if (m) {
          const mm = [m[1], m[2], m[3]].map((v) => num(v) * scale(m));
          if (mm.every(Number.isFinite)) return { mm, line: k + 1 };
        }
      }
    }
  }
  return null;
}

function setOffsetMm(mm, note) {
  OFFSET_IDS.forEach((id, k) => { document.getElementById(id).value = String(Number(mm[k].toFixed(3))); });
  setText("prog-off-note", note);
  offerOffset();
}

const offsetKey = (m) => (m ? m.map((v) => v.toFixed(7)).join(",") : "");

// The offset typed, in metres ({ m }), or why not ({ error, field }, in the operator's words).
function readOffset() {
  const m = [];
  for (const [k, id] of OFFSET_IDS.entries()) {
    const parsed = parseDecimal(document.getElementById(id).value);
    if (parsed.error) return { error: `work offset ${"XYZ"[k]} ${parsed.error}`, field: id };
    if (Math.abs(parsed.value) > 10000) {
      return { error: `work offset ${"XYZ"[k]}: ${parsed.value} mm is beyond any reach (at most 10 m)`, field: id };
    }
    m.push(parsed.value / 1000);
  }
  return { m };
}

// The text states an offset the fields do not hold: offer it (a button), else hide it.
function offerOffset() {
  const button = document.getElementById("prog-off-use");
  const stated = statedOffset(textBox().value);
  const now = readOffset();
  const differs = Boolean(stated && (!now.m || offsetKey(now.m) !== offsetKey(stated.mm.map((v) => v / 1000))));
  button.hidden = !differs;
  if (differs) {
    button.textContent = `Use the program's (${mmText(stated.mm)}) mm`;
    button.title = `line ${stated.line} of the program states its work offset`;
    button.dataset.line = String(stated.line);
  }
}

function useStatedOffset() {
  const stated = statedOffset(textBox().value);
  if (stated) setOffsetMm(stated.mm, `work offset from the program's line ${stated.line}`);
  edited();
}

// Opened text (a file, a library entry): the offset it states, else the one it was last
// sent with (a library entry), else the config's.
function offsetForOpened(text, keptM = null) {
  const stated = statedOffset(text);
  if (stated) setOffsetMm(stated.mm, `work offset from the program's line ${stated.line}`);
  else if (keptM) setOffsetMm(keptM.map((v) => v * 1000), "work offset as it was last sent");
  else setOffsetMm(configOffsetMm, "work offset: the configuration's");
}

// The name a program is kept under: the file's while the text is the file's.
function programName() {
  const text = textBox().value;
  if (loaded && loaded.text === text) return loaded.name;
  return loaded ? `${loaded.name} (edited)`.slice(0, 120) : "unsaved";
}

// The label beside "open a file": the file's name only while the text is the file's.
function showFileName() {
  const text = textBox().value;
  const label = !text ? "" : loaded && loaded.text === text ? loaded.name : "edited, unsaved";
  const out = document.getElementById("prog-file-name");
  out.textContent = label;
  out.title = label && loaded && loaded.text !== text ? `changed since ${loaded.name} was opened` : "";
}

let library = []; // GET /api/programs/library's programs

async function refreshLibrary() {
  try {
    library = (await get("/api/programs/library")).programs;
  } catch {
    return; // the status poll shows the connection banner; keep the list shown
  }
  const select = document.getElementById("prog-library");
  const chosen = select.value;
  const when = (s) => new Date(s * 1000).toLocaleString([], { dateStyle: "short", timeStyle: "short" });
  const size = (b) => (b < 10240 ? `${b} B` : `${(b / 1024).toFixed(0)} kB`);
  const count = library.length;
  select.innerHTML = `<option value="">${count ? `${count} program${count === 1 ? "" : "s"} sent before: choose one` : "no program kept yet"}</option>` +
    library.map((e) => `<option value="${escape(e.id)}" title="${escape(e.first)}">${escape(e.name)} · ${e.lines} lines, ` +
      `${size(e.bytes)} · ${escape(e.action)} ${escape(when(e.sent_at))}</option>`).join("");
  if (library.some((e) => e.id === chosen)) select.value = chosen;
  select.dataset.count = String(count);
  document.getElementById("prog-library-open").disabled = !select.value;
}

async function openFromLibrary() {
  const id = document.getElementById("prog-library").value;
  if (!id) return;
  try {
    const entry = await get(`/api/programs/library/${encodeURIComponent(id)}`);
    textBox().value = entry.gcode;
    loaded = { name: entry.name, text: entry.gcode };
    textBox().scrollTop = 0;
    offsetForOpened(entry.gcode, entry.work_offset_m);
    setText("prog-library-note", `opened ${entry.name}`);
    edited();
  } catch (err) {
    setText("prog-library-note", `not opened: ${operatorText(err).text}`);
  }
}

// ---- the dry run on the twin ----

const dryKey = () => `${textBox().value}\u0000${offsetKey(readOffset().m)}`;

function setDry(text, kind = "") {
  const out = document.getElementById("prog-dry-result");
  out.textContent = text;
  out.className = `preview ${kind}`;
  document.getElementById("prog-dry-box").hidden = false;
}

function showDryRun(answer, text) {
  const source = text.split("\n");
  const rows = answer.lines.filter((e) => e.max_m !== null && e.max_m !== undefined);
  const top = rows.reduce((a, e) => (!a || e.max_m > a.max_m ? e : a), null);
  worst = top ? top.line : null;
  const mmOf = (v) => (v === null || v === undefined ? "–" : (v * 1000).toFixed(3));
  document.getElementById("prog-dry-rows").innerHTML = answer.lines.map((e) =>
    `<tr data-line="${e.line}"${top && e.line === top.line ? ` class="worst" title="the worst line"` : ""} tabindex="0">` +
    `<td>${e.line}</td><td class="num">${mmOf(e.rmse_m)}</td><td class="num">${mmOf(e.max_m)}</td>` +
    `<td class="num">${e.samples}</td><td><code>${escape((source[e.line - 1] || "").trim().slice(0, 60))}</code></td></tr>`).join("");
  document.getElementById("prog-dry-table").hidden = !answer.lines.length;
  const axes = answer.rmse_m.map((v) => (v * 1000).toFixed(3)).join(", ");
  const verdict = answer.ok ? "" : " (the check fails: this program is refused before it runs)";
  setDry(`predicted over ${fixed(answer.duration_s, 2)} s: RMSE x, y, z ${axes} mm, ` +
    `max ${mmOf(answer.max_m)} mm${top ? `, worst on line ${top.line}` : ""}${verdict}`, answer.ok ? "ok" : "bad");
  const out = document.getElementById("prog-dry-result");
  out.dataset.answers = String(Number(out.dataset.answers || 0) + 1);
  if (worst) reveal(worst);
  paintLines();
}

async function dryRun() {
  const text = textBox().value;
  if (!text.trim()) {
    setDry("nothing to play: paste or open a program", "bad");
    return;
  }
  const offset = readOffset();
  if (offset.error) {
    setDry(`not played: ${offset.error}`, "bad");
    document.getElementById(offset.field).focus();
    return;
  }
  const key = dryKey();
  const body = {
    gcode: text, work_offset_m: offset.m, name: programName(),
    feedforward: document.getElementById("prog-ff").checked,
  };
  const lasts = checked && current() && checked.report ? checked.report.duration_s : null;
  const progress = document.getElementById("prog-dry-progress");
  const started = performance.now();
  const tick = () => setDry(`playing the program on the twin (nothing moves)… ${((performance.now() - started) / 1000).toFixed(0)} s` +
    (lasts !== null ? ` (a ${fixed(lasts, 1)} s program)` : ""));
  dryBusy = true;
  worst = null;
  paintLines();
  document.getElementById("prog-dry-table").hidden = true;
  progress.hidden = false;
  progress.removeAttribute("value"); // indeterminate: the server answers once, at the end
  tick();
  const timer = setInterval(tick, 500);
  updateButtons();
  try {
    const answer = await post("/api/programs/dry-run", body);
    clearInterval(timer);
    dryText = key;
    showDryRun(answer, text);
    if (dryKey() !== key) edited(); // typed on meanwhile
  } catch (err) {
    clearInterval(timer);
    dryText = null;
    const detail = err.body && typeof err.body.detail === "string" ? err.body.detail : null;
    if (err.status === 422 && err.body && err.body.line) {
      setDry(`dry run: cannot be read (line ${err.body.line}${err.body.word ? `, word "${err.body.word}"` : ""}): ${detail}`, "bad");
      markLine(err.body.line);
    } else if (err.status === 422 && detail) {
      setDry(`dry run refused: ${metresToMm(detail.replace(/^gcode: /, "").replace(/^work_offset_m(\.\d)?: /, "work offset: "))}`, "bad");
    } else {
      setDry(`dry run not done: ${operatorText(err).text}`, "bad");
    }
    const out = document.getElementById("prog-dry-result");
    out.dataset.answers = String(Number(out.dataset.answers || 0) + 1);
  } finally {
    clearInterval(timer);
    progress.hidden = true;
    dryBusy = false;
    updateButtons();
    refreshLibrary();
  }
}

function onDryClick(event) {
  const row = event.target.closest("tr[data-line]");
  if (row) markLine(Number(row.dataset.line));
}

async function loadDefaults() {
  try {
    const defaults = await get("/api/programs/defaults");
    configOffsetMm = defaults.work_offset_m.map((v) => v * 1000);
  } catch {
    return; // keep 0, 0, 0 shown; the status poll says why the server does not answer
  }
  if (!textBox().value.trim()) offsetForOpened("");
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

// the check speaks for what is in the box now: the same text and work offset
function current() {
  const offset = readOffset();
  return Boolean(checked && checked.text === textBox().value && offset.m && checked.offset === offsetKey(offset.m));
}

function runnable() {
  return Boolean(checked && checked.report && checked.report.ok && current() && !running);
}

function updateButtons() {
  const run = document.getElementById("prog-run");
  run.disabled = !runnable();
  run.title = run.disabled ? (running ? "a program is running" : "check the program first (Run needs a passing check of this text)") : "";
  document.getElementById("prog-abort").disabled = !running;
  document.getElementById("prog-check").disabled = checking;
  document.getElementById("prog-dry").disabled = dryBusy;
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
    ["work offset (G54)", Array.isArray(report.work_offset_m) ? `(${mmText(report.work_offset_m.map((v) => v * 1000))}) mm` : "–"],
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
function showReport(report, text, offset) {
  checked = { text, offset, report };
  const n = report.violations.length;
  const lines = new Set(report.violations.map((v) => v.line)).size;
  const folded = report.violations.filter(isFolded).length;
  setResult(report.ok ? `passes: ${fixed(report.duration_s, 2)} s, path ${fixed(report.length_m * 1000, 1)} mm` :
    `fails: ${n} violation${n === 1 ? "" : "s"} on ${lines} line${lines === 1 ? "" : "s"}` +
    (folded ? ` (the first cause of each shown, ${folded} more folded under them)` : ""), report.ok ? "ok" : "bad", true);
  document.getElementById("prog-figures").innerHTML = figures(report);
  document.getElementById("prog-figures").classList.remove("stale");
  showViolations(report.violations);
  markLine(null);
  showProgram(report);
  updateButtons();
}

// A program that cannot be read (422 {detail, line, word}): its line marked and named.
function showUnreadable(body, text, offset) {
  checked = { text, offset, report: null };
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
  const offset = readOffset();
  if (offset.error) {
    setResult(`not checked: ${offset.error}`, "bad", true);
    document.getElementById(offset.field).focus();
    return;
  }
  const key = offsetKey(offset.m);
  checking = true;
  updateButtons();
  setResult("checking… (every loop sample of the path, on the virtual robot)");
  try {
    const body = { gcode: text, work_offset_m: offset.m, name: programName() };
    showReport(await post("/api/programs/check", body), text, key);
  } catch (err) {
    if (err.status === 422 && err.body && err.body.line) showUnreadable(err.body, text, key);
    else setResult(`not checked: ${operatorText(err).text}`, "bad", true);
  } finally {
    checking = false;
    if (checked && !current()) edited(); // typed on meanwhile
    updateButtons();
    refreshLibrary();
  }
}

// The text (or the work offset) changed: the check no longer speaks for it, nor the dry run.
function edited() {
  renderGutter();
  showFileName();
  offerOffset();
  if (checked && !current()) {
    if (checked.report) setResult("changed since the check: press Check again (Run waits for it)", "");
    checked = null;
    markLine(null);
    document.getElementById("prog-figures").classList.add("stale"); // the last check's, greyed
  }
  if (dryText !== null && dryText !== dryKey()) {
    dryText = null;
    worst = null;
    document.getElementById("prog-dry-rows").querySelectorAll("tr").forEach((tr) => tr.classList.add("stale"));
    setDry("changed since the dry run: press Dry run again", "");
    paintLines();
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
  const options = runOptions(); // programcontrol.js: feed override, optional stop, from line
  if (!options) return; // a "run from line" that is not a line number: said there, nothing sent
  const key = checked.offset;
  const body = {
    gcode: text, feedforward: document.getElementById("prog-ff").checked,
    work_offset_m: readOffset().m, name: programName(), ...options,
  };
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
      showReport(refused, text, key);
      setResult(`not started: ${document.getElementById("prog-result").textContent}`, "bad");
    } else if (refused) {
      checked = null;
      showViolations(refused.violations);
      setResult(`not started: ${refused.violations.length} violation(s) from where the robot is now`, "bad");
      updateButtons();
    } else if (err.status === 422 && err.body && err.body.line) {
      showUnreadable(err.body, text, key);
    } else {
      showError(err);
    }
  } finally {
    refreshLibrary();
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
  const text = await file.text();
  textBox().value = text;
  loaded = { name: file.name, text };
  textBox().scrollTop = 0;
  document.getElementById("prog-library").value = ""; // the text is the file's now
  document.getElementById("prog-library-open").disabled = true;
  setText("prog-library-note", "");
  offsetForOpened(text);
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
  document.getElementById("prog-dry").addEventListener("click", dryRun);
  const dryRows = document.getElementById("prog-dry-rows");
  dryRows.addEventListener("click", onDryClick);
  dryRows.addEventListener("keydown", (event) => { if (event.key === "Enter") onDryClick(event); });
  for (const id of OFFSET_IDS) document.getElementById(id).addEventListener("input", edited);
  document.getElementById("prog-off-use").addEventListener("click", useStatedOffset);
  const select = document.getElementById("prog-library");
  select.addEventListener("change", () => { document.getElementById("prog-library-open").disabled = !select.value; });
  document.getElementById("prog-library-open").addEventListener("click", openFromLibrary);
  renderGutter();
  updateButtons();
  loadDefaults();
  refreshLibrary();
  pollRuns();
  setInterval(() => { if (running || performance.now() - polledAt >= IDLE_POLL_MS) pollRuns(); }, RUNS_POLL_MS);
  // another tab or the CLI may have sent one: the list kept fresh, never while it is open
  setInterval(() => { if (document.activeElement !== select) refreshLibrary(); }, LIBRARY_POLL_MS);
}
