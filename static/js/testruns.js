// The test-run form: a chooser of every run type the API starts, each type's fields made from
// its body's JSON schema (GET /api/tests: fields, bounds, defaults), so a new run type needs no
// page code. Fields are shown in mm, degrees, Hz and s (a field's SI unit is its name's
// suffix: _m, _rad, _hz, _s) and converted to SI exactly for the body; a field that is not a
// number or is outside its bounds is refused here, named in operator words, and nothing is
// sent. Before a start, every change is previewed (POST /api/tests/<name>/check: planned and
// checked from where the robot is, nothing moves). The running run comes from the server
// (runs.js's poll: its kind, progress and parameters), so a reload or another tab shows it.
// Hold-in-world follows the drone's pose: the chooser sends the operator to its own panel.

import { fixed, get, post } from "./api.js";
import { command } from "./control.js";
import { operatorText, parseDecimal, setText, showError, showMessage } from "./ui.js";
import { wrist } from "./wrist.js";

const PREVIEW_DELAY_MS = 300;
const AXES = ["x", "y", "z"];
const HOLD = "hold"; // the chooser's entry for hold-in-world (its own panel, its own body)
const ROUND = 1e6; // shown values: SI defaults to 6 decimals of the shown unit

// A field's unit from its SI name's suffix: the word the page shows, and both conversions.
// mm -> m divides by 1000 (the nearest double to the typed decimal in metres, as the API
// would parse "0.0125"); degrees -> rad as Python's math.radians.
const UNITS = [
  { suffix: "_m", word: "mm", toSI: (v) => v / 1000, fromSI: (v) => v * 1000 },
  { suffix: "_rad", word: "deg", toSI: (v) => v * (Math.PI / 180), fromSI: (v) => v * (180 / Math.PI) },
  { suffix: "_hz", word: "Hz", toSI: (v) => v, fromSI: (v) => v },
  { suffix: "_s", word: "s", toSI: (v) => v, fromSI: (v) => v },
];
const NO_UNIT = { suffix: "", word: "", toSI: (v) => v, fromSI: (v) => v };
// operator words for a few field names (the rest: the name without its unit, spaces for _)
const WORDS = {
  feedforward: "feed-forward", f0: "start frequency", f1: "end frequency", size: "step size",
  points: "point", times: "time",
};

let types = []; // the listed run types, each { name, doc, start, check, fields }
let chosen = null; // the chosen type's name
const typed = new Map(); // name -> { field key -> value } typed per type, kept across switches
let previewTimer = null;
let previewAsked = 0; // the newest preview's number: an older answer is not shown over it
let refresh = () => {}; // runs.js's table refresh, after a start or an abort
let active = null; // { id, kind, description, progress, at, filled } of the running run
let previewKey = "";

// ---- the fields, from a type's JSON schema ---------------------------------------------------

function unitOf(name) {
  return UNITS.find((u) => name.endsWith(u.suffix)) || NO_UNIT;
}

function labelOf(base) {
  const wristField = base.startsWith("phi_");
  const words = (wristField ? base.slice(4) : base).replace(/_/g, " ");
  const said = WORDS[words] || words;
  return wristField ? `wrist ${said}` : said;
}

// One field: key (the input's name, the API name without its unit), label, unit, kind
// (number, integer, axis, boolean, vector, list: a column of the points table), its SI
// bounds and default.
function fieldOf(name, p, required) {
  const unit = unitOf(name);
  const base = unit.suffix ? name.slice(0, -unit.suffix.length) : name;
  const items = p.items || {};
  let kind = p.type;
  if (p.type === "integer" && name === "axis") kind = "axis";
  if (p.type === "array") {
    if (items.type === "array") kind = "points";
    else if (p.minItems === 3 && p.maxItems === 3) kind = "vector";
    else kind = "list";
  }
  const bounded = kind === "points" ? items.items || {} : kind === "vector" || kind === "list" ? items : p;
  const example = Array.isArray(p.examples) ? p.examples[0] : undefined;
  return {
    name, key: base, label: labelOf(base), unit, kind, required,
    min: bounded.minimum, max: bounded.maximum,
    minOpen: bounded.exclusiveMinimum, maxOpen: bounded.exclusiveMaximum,
    minItems: p.minItems, maxItems: p.maxItems,
    value: p.default !== undefined ? p.default : example,
    integer: bounded.type === "integer",
    wrist: name.startsWith("phi_"),
  };
}

function typeOf(entry) {
  const schema = entry.schema || {};
  const required = new Set(schema.required || []);
  const fields = Object.entries(schema.properties || {})
    .map(([name, p]) => fieldOf(name, p, required.has(name)))
    .filter((f) => !f.wrist || wrist.enabled); // nothing about a wrist shows without one
  return { ...entry, fields };
}

const shown = (f, si) => String(Math.round(f.unit.fromSI(si) * ROUND) / ROUND);
const unitText = (f) => (f.unit.word ? ` ${f.unit.word}` : "");

// ---- rendering ------------------------------------------------------------------------------

function input(name, value, aria) {
  const el = document.createElement("input");
  // text, not number: a number field drops a decimal comma in some locales (12,5 -> 125)
  Object.assign(el, { name, type: "text", inputMode: "decimal", autocomplete: "off", value });
  el.setAttribute("aria-label", aria);
  return el;
}

function labelled(text, control) {
  const label = document.createElement("label");
  label.append(`${text} `, control);
  return label;
}

function vectorTable(fields) {
  const table = document.createElement("table");
  table.className = "axes";
  table.innerHTML = `<thead><tr><th></th>${AXES.map((a) => `<th scope="col">${a}</th>`).join("")}</tr></thead>`;
  const body = table.createTBody();
  for (const f of fields) {
    const row = body.insertRow();
    row.innerHTML = `<th scope="row">${f.label}${unitText(f)}</th>`;
    AXES.forEach((a, i) => {
      const value = f.value === undefined ? "" : shown(f, f.value[i]);
      row.insertCell().append(input(`${f.key}${i}`, value, `${f.label} ${a}${unitText(f)}`));
    });
  }
  return table;
}

// The points table (waypoints): one row per point, the list fields as its columns.
function listTable(fields) {
  const wrap = document.createElement("div");
  wrap.className = "run-list";
  const table = document.createElement("table");
  table.className = "axes run-points";
  const heads = fields.flatMap((f) => (f.kind === "points"
    ? AXES.map((a) => `<th scope="col">${a}${unitText(f)}</th>`)
    : [`<th scope="col">${f.label}${unitText(f)}</th>`]));
  table.innerHTML = `<thead><tr><th scope="col">#</th>${heads.join("")}<th></th></tr></thead><tbody></tbody>`;
  const rows = Math.max(...fields.map((f) => (Array.isArray(f.value) ? f.value.length : f.minItems || 2)));
  for (let r = 0; r < rows; r += 1) addRow(table.tBodies[0], fields, r);
  const add = document.createElement("button");
  Object.assign(add, { type: "button", textContent: "Add point", className: "run-add" });
  add.addEventListener("click", () => {
    const body = table.tBodies[0];
    addRow(body, fields, body.rows.length, true);
    renumber(body);
    schedulePreview();
  });
  wrap.append(table, add);
  return wrap;
}

function addRow(body, fields, r, copyLast = false) {
  const row = body.insertRow();
  row.insertCell().textContent = String(r + 1);
  const last = body.rows.length > 1 ? body.rows[body.rows.length - 2] : null;
  for (const f of fields) {
    const values = Array.isArray(f.value) ? f.value : [];
    const cols = f.kind === "points" ? AXES.map((_, i) => i) : [null];
    for (const i of cols) {
      let value = "";
      if (copyLast && last) { // a new point: where the last one is, a second later
        const before = last.querySelector(`input[data-field="${f.key}"]${i === null ? "" : `[data-col="${i}"]`}`);
        const parsed = parseDecimal(before ? before.value : "");
        value = parsed.error ? "" : String(i === null && f.unit.word === "s" ? parsed.value + 1 : parsed.value);
      } else if (values[r] !== undefined) {
        value = shown(f, i === null ? values[r] : values[r][i]);
      }
      const el = input("", value, "");
      el.dataset.field = f.key;
      if (i !== null) el.dataset.col = String(i);
      row.insertCell().append(el);
    }
  }
  const remove = document.createElement("button");
  Object.assign(remove, { type: "button", textContent: "×", className: "run-remove" });
  remove.addEventListener("click", () => {
    const tbody = row.parentElement;
    row.remove();
    renumber(tbody);
    schedulePreview();
  });
  row.insertCell().append(remove);
  renumber(body);
}

// Row numbers and each input's name and label follow the rows (after an add or a remove).
function renumber(body) {
  [...body.rows].forEach((row, r) => {
    row.cells[0].textContent = String(r + 1);
    row.querySelectorAll("input").forEach((el) => {
      const f = current().fields.find((x) => x.key === el.dataset.field);
      const col = el.dataset.col;
      el.name = `${f.key}-${r}${col === undefined ? "" : `-${col}`}`;
      el.setAttribute("aria-label", `${f.label} ${r + 1}${col === undefined ? "" : ` ${AXES[col]}`}${unitText(f)}`);
    });
    row.querySelector(".run-remove").setAttribute("aria-label", `remove point ${r + 1}`);
  });
}

function scalarRow(fields) {
  const row = document.createElement("div");
  row.className = "row run-scalars";
  for (const f of fields) {
    if (f.kind === "boolean") {
      const box = document.createElement("input");
      Object.assign(box, { name: f.key, type: "checkbox", checked: Boolean(f.value) });
      const label = labelled("", box);
      label.className = "toggle";
      label.append(f.label);
      row.append(label);
    } else if (f.kind === "axis") {
      const select = document.createElement("select");
      select.name = f.key;
      select.setAttribute("aria-label", f.label);
      AXES.slice(f.min || 0, (f.max ?? 2) + 1).forEach((a, i) => select.add(new Option(a, String(i + (f.min || 0)))));
      select.value = String(f.value ?? 0);
      row.append(labelled(f.label, select));
    } else {
      const value = f.value === undefined ? "" : shown(f, f.value);
      row.append(labelled(`${f.label}${unitText(f)}`, input(f.key, value, `${f.label}${unitText(f)}`)));
    }
  }
  return row;
}

const current = () => types.find((t) => t.name === chosen);

function render() {
  const holder = document.getElementById("run-fields");
  const hold = chosen === HOLD;
  document.getElementById("run-hold").hidden = !hold;
  document.getElementById("run-form").hidden = hold;
  document.getElementById("run-start").hidden = hold;
  holder.replaceChildren();
  const type = current();
  // the body's own description, without its SI units (the fields say theirs)
  const doc = type ? String((type.schema || {}).description || "") : "";
  setText("run-doc", doc.replace(/ \[(m|rad|s|Hz)\]/g, ""));
  if (!type) return;
  const of = (...kinds) => type.fields.filter((f) => kinds.includes(f.kind));
  if (of("vector").length) holder.append(vectorTable(of("vector")));
  if (of("points", "list").length) holder.append(listTable(of("points", "list")));
  holder.append(scalarRow(of("number", "integer", "axis", "boolean")));
  restoreTyped(type.name);
}

// What was typed in a type's form is kept when another type is chosen, and back with it.
function keepTyped() {
  if (!current()) return;
  const form = document.getElementById("run-form");
  const values = {};
  for (const el of form.querySelectorAll("#run-fields input, #run-fields select")) {
    values[el.name] = el.type === "checkbox" ? el.checked : el.value;
  }
  values["#rows"] = form.querySelectorAll(".run-points tbody tr").length;
  typed.set(chosen, values);
}

function restoreTyped(name) {
  const values = typed.get(name);
  if (!values) return;
  const body = document.querySelector("#run-fields .run-points tbody");
  if (body) {
    while (body.rows.length < values["#rows"]) addRow(body, current().fields.filter((f) => f.kind === "points" || f.kind === "list"), body.rows.length);
    while (body.rows.length > values["#rows"]) body.rows[body.rows.length - 1].remove();
    renumber(body);
  }
  for (const el of document.querySelectorAll("#run-fields input, #run-fields select")) {
    if (!(el.name in values)) continue;
    if (el.type === "checkbox") el.checked = values[el.name];
    else el.value = values[el.name];
  }
}

function choose(name) {
  if (name === chosen) return;
  keepTyped();
  chosen = name;
  const select = document.getElementById("run-type");
  if (select.value !== name) select.value = name;
  render();
  if (name !== HOLD) schedulePreview();
}

// ---- the body: shown units -> SI, refused here in the operator's words ----------------------

function readNumber(el, f, problems) {
  const aria = el.getAttribute("aria-label") || f.label;
  const parsed = parseDecimal(el.value);
  let problem = parsed.error || null;
  let si = null;
  if (!problem) {
    si = f.unit.toSI(parsed.value);
    const bound = (v) => `${shown(f, v)}${unitText(f)}`;
    if (f.integer && !Number.isInteger(parsed.value)) problem = "must be a whole number";
    else if (f.minOpen !== undefined && !(si > f.minOpen)) problem = `must be more than ${bound(f.minOpen)}`;
    else if (f.min !== undefined && si < f.min) problem = `${el.value.trim()}${unitText(f)} is below the smallest allowed, ${bound(f.min)}`;
    else if (f.maxOpen !== undefined && !(si < f.maxOpen)) problem = `must be less than ${bound(f.maxOpen)}`;
    else if (f.max !== undefined && si > f.max) problem = `${el.value.trim()}${unitText(f)} is over the largest allowed, ${bound(f.max)}`;
  }
  el.setAttribute("aria-invalid", problem ? "true" : "false");
  if (problem) problems.push(`${aria}: ${problem}`);
  return problem ? null : si;
}

// The chosen type's body in SI, or { error } naming the first field refused (its box marked).
function runBody() {
  const type = current();
  const form = document.getElementById("run-form");
  const problems = [];
  const body = {};
  for (const f of type.fields) {
    if (f.kind === "boolean") body[f.name] = form.elements[f.key].checked;
    else if (f.kind === "axis") body[f.name] = Number(form.elements[f.key].value);
    else if (f.kind === "vector") body[f.name] = AXES.map((_, i) => readNumber(form.elements[`${f.key}${i}`], f, problems));
    else if (f.kind === "number" || f.kind === "integer") body[f.name] = readNumber(form.elements[f.key], f, problems);
  }
  const rows = [...form.querySelectorAll(".run-points tbody tr")];
  for (const f of type.fields.filter((x) => x.kind === "points" || x.kind === "list")) {
    body[f.name] = rows.map((row) => {
      const cells = [...row.querySelectorAll(`input[data-field="${f.key}"]`)];
      const values = cells.map((el) => readNumber(el, f, problems));
      return f.kind === "points" ? values : values[0];
    });
  }
  const list = type.fields.find((x) => x.kind === "points" || x.kind === "list");
  if (list && list.minItems && rows.length < list.minItems) problems.push(`give at least ${list.minItems} points (${rows.length} now)`);
  if (list && list.maxItems && rows.length > list.maxItems) problems.push(`give at most ${list.maxItems} points (${rows.length} now)`);
  return problems.length ? { error: problems[0] } : body;
}

// The server's words with the API's field names as the page names them ("step_at_s" ->
// "step at (s)"), then in mm and degrees.
function serverText(err) {
  const type = current();
  // pydantic's framing of a body's refusal ("Body: Value error, ...") is the API's
  let message = String(err && err.message ? err.message : err).replace(/^body: /i, "").replace(/Value error, /g, "");
  for (const f of type ? type.fields : []) {
    message = message.replace(new RegExp(`\\b${f.name}\\b`, "g"), `${f.label}${f.unit.word ? ` (${f.unit.word})` : ""}`);
  }
  return operatorText({ ...err, message, status: err && err.status }).text;
}

// ---- preview, start, abort ------------------------------------------------------------------

async function preview() {
  const type = current();
  const out = document.getElementById("run-preview");
  if (!type) return;
  const body = runBody();
  if (body.error) { // nothing asked of the server about a form that is not numbers
    out.textContent = body.error;
    out.title = "";
    out.className = "preview bad";
    return;
  }
  const asked = ++previewAsked;
  try {
    const c = await post(type.check, body);
    if (asked !== previewAsked || type !== current()) return; // a newer preview is on its way
    const speed = c.peak_joint_speed_rad_s === null ? "–" : fixed(c.peak_joint_speed_rad_s, 2);
    const head = `peak joint speed ${speed} rad/s (limit ${fixed(c.joint_speed_limit_rad_s, 1)}), ` +
      `peak platform speed ${fixed(c.peak_speed_m_s, 2)} m/s: `;
    out.textContent = head + (c.feasible ? "feasible" : serverText({ message: c.detail }));
    out.title = c.feasible ? "" : `server: ${c.detail}`;
    out.className = c.feasible ? "preview ok" : "preview bad";
  } catch (err) {
    if (asked !== previewAsked) return;
    out.textContent = serverText(err);
    out.title = `server: ${err.message}`;
    out.className = "preview bad";
  }
}

function schedulePreview() {
  clearTimeout(previewTimer);
  previewTimer = setTimeout(preview, PREVIEW_DELAY_MS);
}

async function start(event) {
  event.preventDefault();
  const type = current();
  if (!type) return;
  const body = runBody();
  if (body.error) {
    showMessage(`Not started: ${body.error}`, "error");
    return;
  }
  try {
    const { run_id } = await command(type.start, body);
    active = { id: run_id, kind: type.name, description: "", progress: null, at: 0, filled: true };
    showMessage(`Run ${run_id} started`);
    refresh();
  } catch (err) {
    const { clearsWhen } = operatorText(err);
    showMessage(`Not started: ${serverText(err)}`, "error", { detail: err.message || "", clearsWhen });
  }
}

function abort() {
  if (active) command(`/api/runs/${active.id}/abort`).then(refresh).catch(showError);
}

// Progress through the test part: the server's figure at the last poll, advanced by the time
// since while the status says the test part is going (approach, timed/hold, stop).
function testShare(phase) {
  const p = active.progress;
  if (phase === "stop") return 1;
  if (!p || !p.test_duration_s) return 0;
  const going = phase === "timed" || phase === "hold";
  const since = going && p.phase === phase ? (performance.now() - active.at) / 1000 : 0;
  return Math.min((p.test_elapsed_s + since) / p.test_duration_s, 1);
}

export function onRunStatus(s) {
  if (!types.length) loadTypes(); // offline at load: listed once the server answers
  // feasibility depends on where the robot starts: re-check when its state changes; a
  // relaxed arm moves on its own (falls, swings): re-check as it moves, to the centimetre
  const where = s.torque ? "" : (s.ee.position_m || []).map((v) => (v === null ? "" : Math.round(v * 100))).join(",");
  const key = `${s.mode}|${s.torque}|${s.estopped}|${s.faults.length}|${where}`;
  if (key !== previewKey && s.mode !== "test" && chosen !== HOLD) {
    previewKey = key;
    schedulePreview();
  }
  const bar = document.getElementById("run-progress");
  const running = Boolean(active) && (s.mode === "test" || s.mode === "hold-world");
  document.getElementById("run-abort").disabled = !running;
  bar.hidden = !running;
  if (!running) {
    setText("run-phase", "");
    setText("run-params", "");
    return;
  }
  bar.value = testShare(s.phase);
  const percent = `${Math.round(bar.value * 100)} %`;
  bar.textContent = percent;
  setText("run-phase", `run ${active.id}: ${s.phase || "starting"} ${percent}`);
  setText("run-params", active.description);
}

// The form shows the running run's type and parameters (mm, deg, Hz, s), once per run.
function fillForm(kind, params) {
  if (!types.some((t) => t.name === kind)) return; // a hold, a program, a joint step
  typed.delete(kind);
  chosen = null;
  choose(kind);
  const form = document.getElementById("run-form");
  const set = (name, f, si) => { if (form.elements[name] && typeof si === "number") form.elements[name].value = shown(f, si); };
  const type = current();
  const lists = type.fields.filter((f) => f.kind === "points" || f.kind === "list");
  const body = form.querySelector(".run-points tbody");
  if (body && lists.length && Array.isArray(params[lists[0].name])) {
    const count = params[lists[0].name].length;
    while (body.rows.length < count) addRow(body, lists, body.rows.length);
    while (body.rows.length > count) body.rows[body.rows.length - 1].remove();
    renumber(body);
  }
  for (const f of type.fields) {
    const si = params[f.name];
    if (si === undefined) continue;
    if (f.kind === "boolean") form.elements[f.key].checked = Boolean(si);
    else if (f.kind === "axis") form.elements[f.key].value = String(si);
    else if (f.kind === "vector") AXES.forEach((_, i) => set(`${f.key}${i}`, f, si[i]));
    else if (f.kind === "points") si.forEach((p, r) => AXES.forEach((_, i) => set(`${f.key}-${r}-${i}`, f, p[i])));
    else if (f.kind === "list") si.forEach((v, r) => set(`${f.key}-${r}`, f, v));
    else set(f.key, f, si);
  }
  schedulePreview();
}

// runs.js's poll: the running run (null: none), followed from the server's record.
export function followRun(run) {
  if (!run) {
    active = null;
    return;
  }
  if (!active || active.id !== run.run_id) active = { id: run.run_id, kind: run.kind, filled: false };
  Object.assign(active, { description: run.description, progress: run.progress, at: performance.now(), run });
  fillOnce();
}

// The running run's type and parameters in the form, once per run (once the types are in).
function fillOnce() {
  if (!active || active.filled || !types.length || !active.run) return;
  fillForm(active.run.kind, active.run.params || {});
  active.filled = true;
}

// ---- the chooser ----------------------------------------------------------------------------

let loading = null;

async function loadTypes() {
  if (loading) return loading;
  loading = (async () => {
    try {
      const listed = await get("/api/tests");
      types = listed.map(typeOf);
      const select = document.getElementById("run-type");
      select.replaceChildren(...types.map((t) => new Option(t.name, t.name)),
        new Option("hold in world (its own panel)", HOLD));
      choose(types[0].name);
      fillOnce(); // a run followed before the types were in
    } catch {
      // offline: the status poll shows the banner; asked again on the next status
    } finally {
      loading = null;
    }
  })();
  return loading;
}

// The Hold-in-world panel (static/js/hold.js): brought into view, its first control focused.
function openHold() {
  const panel = document.querySelector("section.hold, #hold");
  if (!panel) {
    setText("run-hold-said", "The Hold-in-world panel is not on this page.");
    return;
  }
  panel.scrollIntoView({ block: "start" });
  const first = panel.querySelector("select, input, button");
  if (first) first.focus({ preventScroll: true });
}

export function startTestRuns(onChange) {
  refresh = onChange;
  const form = document.getElementById("run-form");
  form.addEventListener("submit", start);
  form.addEventListener("input", schedulePreview);
  form.addEventListener("change", schedulePreview);
  document.getElementById("run-type").addEventListener("change", (e) => choose(e.target.value));
  document.getElementById("run-abort").addEventListener("click", abort);
  document.getElementById("run-hold-go").addEventListener("click", openHold);
  setText("run-preview", "checking…");
  loadTypes();
}
