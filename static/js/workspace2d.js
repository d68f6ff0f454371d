// A 2D view of the workspace without WebGL: a top section (x-y at the platform's height)
// and a side section (x-z through the platform's y) of the region the gate accepts
// (GET /api/workspace/section), with the robot's measured point, the goal the loop uses,
// the goal typed in the Go-to form and, when that is outside, the nearest reachable point
// (GET /api/workspace/nearest) with a button that sends it as the goal, and a scale bar in
// mm.
//
// Light by design, so the e-stop stays fast: canvas 2D only, sections fetched when the cut
// moved a few mm (cached by the server), and a redraw only when something drawn changed,
// at most every MIN_FRAME_MS.

import { get } from "./api.js";
import { goTo } from "./control.js";
import { setText } from "./ui.js";
import { currentPhiRad, hasTool, wrist } from "./wrist.js";

const MIN_FRAME_MS = 100; // at most ~10 redraws a second
// Cuts on a 5 mm grid: a sinusoid's z sweep asks for a few dozen sections once, then the
// server's cache answers (each new one is ~20k IK solutions on the server's CPU).
const LEVEL_STEP_M = 0.005;
const TYPED_DEBOUNCE_MS = 150;
const COLOURS = {
  reachable: "#d3f9d8", outside: "#f1f3f5", edge: "#2b8a3e", robot: "#1864ab", platform: "#862e9c",
  goal: "#343a40", typed: "#e8590c", nearest: "#9c36b5", text: "#495057",
  program: "#0b7285", violation: "#c92a2a",
};
const PROGRAM_POINTS = 2000; // at most this many of a checked path's points are drawn
const XYZ = { x: 0, y: 1, z: 2 };

const views = {
  top: { plane: "xy", levelAxis: 2, fallback: -0.24, section: null, image: null, loading: false, error: null },
  side: { plane: "xz", levelAxis: 1, fallback: 0.0, section: null, image: null, loading: false, error: null },
};
// robot: the tool tip (the point goals are for); platform: its centre, drawn too when a tool
// offset is set; phi: the wrist angle a goal from here keeps [rad]
// typedPhi: the wrist angle of the typed goal [rad] (the form's φ; 0 without a wrist)
const seen = {
  robot: null, platform: null, phi: 0, goal: null, typed: null, typedPhi: 0, inside: true, nearest: null,
};
const PHI_STEP_RAD = Math.PI / 180; // a new section when the wrist's goal turned a degree
let drawnKey = "";
let lastDraw = 0;
let drawTimer = null;
let typedTimer = null;
const BUSY_RETRY_MS = 1000; // a typed goal's check refused as busy is asked again after this
let typedAsked = 0; // the latest /nearest request; older answers are dropped
// the last checked program (programs.js hands it here): path and violation points [m]
let program = null; // { path: [[x, y, z], ...], violations: [[x, y, z], ...] }
let programVersion = 0;

const mmText = (p) => p.map((v) => (v * 1000).toFixed(1)).join(", ");

// The level of a view's cut [m]: through the robot's point (measured, else commanded).
function levelOf(view) {
  return seen.robot ? seen.robot[view.levelAxis] : view.fallback;
}

// With a tool off the wrist's axis the accepted region of tips turns with the wrist: the
// sections are cut at the angle a goal from here keeps (the wrist's goal).
async function fetchSection(view) {
  const level = Number((Math.round(levelOf(view) / LEVEL_STEP_M) * LEVEL_STEP_M).toFixed(3));
  const phi = wrist.enabled ? Math.round(seen.phi / PHI_STEP_RAD) * PHI_STEP_RAD : 0;
  const same = view.section && Math.abs(view.section.at_m - level) < 1e-4 &&
    Math.abs((view.section.phi_rad || 0) - phi) < PHI_STEP_RAD / 2;
  if (view.loading || same) return;
  view.loading = true;
  try {
    const query = new URLSearchParams({ plane: view.plane, at_m: String(level) });
    if (wrist.enabled) query.set("phi_rad", phi.toFixed(6));
    view.section = await get(`/api/workspace/section?${query}`);
    view.image = sectionImage(view.section);
    view.error = null;
    schedule();
  } catch (err) {
    view.error = err.message;
    schedule();
  } finally {
    view.loading = false;
  }
}

// The section's grid as an offscreen canvas, one pixel per cell (v up).
function sectionImage(section) {
  const width = section.u_m.length, height = section.v_m.length;
  const image = document.createElement("canvas");
  image.width = width;
  image.height = height;
  const ctx = image.getContext("2d");
  const pixels = ctx.createImageData(width, height);
  const fill = [hex(COLOURS.reachable), hex(COLOURS.outside)];
  section.reachable.forEach((row, j) => {
    const y = height - 1 - j;
    for (let i = 0; i < width; i += 1) {
      const colour = fill[row[i] === "1" ? 0 : 1];
      pixels.data.set([...colour, 255], 4 * (y * width + i));
    }
  });
  ctx.putImageData(pixels, 0, 0);
  return image;
}

function hex(colour) {
  return [1, 3, 5].map((k) => parseInt(colour.slice(k, k + 2), 16));
}

// Canvas pixels of (u, v) [m]: equal scales, the section's extent centred.
function transform(canvas, section) {
  const cellU = section.u_m[1] - section.u_m[0], cellV = section.v_m[1] - section.v_m[0];
  const u0 = section.u_m[0] - cellU / 2, u1 = section.u_m[section.u_m.length - 1] + cellU / 2;
  const v0 = section.v_m[0] - cellV / 2, v1 = section.v_m[section.v_m.length - 1] + cellV / 2;
  const pad = 18;
  const scale = Math.min((canvas.width - 2 * pad) / (u1 - u0), (canvas.height - 2 * pad) / (v1 - v0));
  const left = (canvas.width - scale * (u1 - u0)) / 2, top = (canvas.height - scale * (v1 - v0)) / 2;
  return {
    box: [left, top, scale * (u1 - u0), scale * (v1 - v0)],
    scale, // [px/m]
    at: (p, view) => {
      const [iu, iv] = view.section.axes.map((a) => XYZ[a]);
      return [left + (p[iu] - u0) * scale, top + (v1 - p[iv]) * scale];
    },
  };
}

function marker(ctx, [x, y], kind) {
  ctx.save();
  ctx.lineWidth = 2;
  ctx.strokeStyle = ctx.fillStyle = COLOURS[kind];
  ctx.beginPath();
  if (kind === "goal") {
    ctx.moveTo(x - 6, y - 6); ctx.lineTo(x + 6, y + 6); ctx.moveTo(x + 6, y - 6); ctx.lineTo(x - 6, y + 6);
    ctx.stroke();
  } else if (kind === "platform") { // a diamond: the platform centre, the tool tip's root
    ctx.moveTo(x, y - 6); ctx.lineTo(x + 6, y); ctx.lineTo(x, y + 6); ctx.lineTo(x - 6, y); ctx.closePath();
    ctx.stroke();
  } else if (kind === "typed") {
    ctx.arc(x, y, 7, 0, 2 * Math.PI);
    ctx.stroke();
  } else {
    ctx.arc(x, y, kind === "robot" ? 5 : 4, 0, 2 * Math.PI);
    ctx.fill();
  }
  ctx.restore();
}

function drawView(name) {
  const view = views[name];
  const canvas = document.getElementById(`ws-${name}`);
  const ctx = canvas.getContext("2d");
  ctx.fillStyle = "#ffffff";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  if (!view.section || !view.image) {
    ctx.fillStyle = COLOURS.text;
    ctx.fillText(view.error ? `no section: ${view.error}` : "loading the workspace…", 10, 20);
    return;
  }
  const t = transform(canvas, view.section);
  ctx.imageSmoothingEnabled = false;
  ctx.drawImage(view.image, ...t.box);
  ctx.strokeStyle = COLOURS.edge;
  ctx.strokeRect(...t.box);
  const [u, v, level] = view.section.axes;
  ctx.fillStyle = COLOURS.text;
  ctx.font = "12px system-ui, sans-serif";
  ctx.fillText(`${u} →   ${v} ↑   cut at ${level} = ${(view.section.at_m * 1000).toFixed(0)} mm`, 6, 13);
  drawScale(ctx, t, canvas);
  if (!view.section.reachable.some((row) => row.includes("1"))) {
    ctx.fillText("nothing reachable at this height: move the platform into the workspace",
      6, canvas.height - 6);
  }
  if (seen.typed) {
    if (!seen.inside && seen.nearest) {
      const [a, b] = [t.at(seen.typed, view), t.at(seen.nearest, view)];
      ctx.save();
      ctx.setLineDash([4, 3]);
      ctx.strokeStyle = COLOURS.nearest;
      ctx.beginPath(); ctx.moveTo(...a); ctx.lineTo(...b); ctx.stroke();
      ctx.restore();
      marker(ctx, b, "nearest");
    }
    marker(ctx, t.at(seen.typed, view), "typed");
  }
  drawProgram(ctx, t, view, canvas);
  if (seen.goal) marker(ctx, t.at(seen.goal, view), "goal");
  if (seen.robot && seen.platform) { // the tool: a line from the platform centre to the tip
    const from = t.at(seen.platform, view), to = t.at(seen.robot, view);
    ctx.save();
    ctx.strokeStyle = COLOURS.platform;
    ctx.beginPath(); ctx.moveTo(...from); ctx.lineTo(...to); ctx.stroke();
    ctx.restore();
    marker(ctx, from, "platform");
    canvas.dataset.platformPx = from.map((c) => Math.round(c)).join(",");
  } else {
    delete canvas.dataset.platformPx;
  }
  if (seen.robot) {
    const at = t.at(seen.robot, view);
    marker(ctx, at, "robot");
    canvas.dataset.robotPx = at.map((c) => Math.round(c)).join(",");
  } else {
    delete canvas.dataset.robotPx;
  }
}

// A scale bar (bottom right): a round length (10, 20, 50, 100 mm...) about a quarter of
// the drawn width, with its length in mm; the canvas records it (data-scale-mm, -px).
function drawScale(ctx, t, canvas) {
  const pxPerMm = t.scale / 1000;
  const wanted = (t.box[2] / 4) / pxPerMm; // [mm]
  const power = 10 ** Math.floor(Math.log10(wanted));
  const lengthMm = [1, 2, 5, 10].map((k) => k * power).filter((v) => v <= wanted).pop() || power;
  const px = lengthMm * pxPerMm;
  const right = t.box[0] + t.box[2] - 8, y = t.box[1] + t.box[3] - 8;
  ctx.save();
  ctx.strokeStyle = ctx.fillStyle = COLOURS.text;
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(right - px, y - 4); ctx.lineTo(right - px, y); ctx.lineTo(right, y); ctx.lineTo(right, y - 4);
  ctx.stroke();
  ctx.font = "11px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.fillText(`${lengthMm} mm`, right - px / 2, y - 6);
  ctx.restore();
  canvas.dataset.scaleMm = String(lengthMm);
  canvas.dataset.scalePx = px.toFixed(2);
}

// The checked program's path projected on the view's plane, its violations as red crosses.
function drawProgram(ctx, t, view, canvas) {
  canvas.dataset.programPoints = program ? String(program.path.length) : "0";
  canvas.dataset.programViolations = program ? String(program.violations.length) : "0";
  if (!program) return;
  ctx.save();
  ctx.strokeStyle = COLOURS.program;
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  program.path.forEach((p, i) => (i ? ctx.lineTo(...t.at(p, view)) : ctx.moveTo(...t.at(p, view))));
  ctx.stroke();
  ctx.strokeStyle = COLOURS.violation;
  ctx.lineWidth = 2;
  ctx.beginPath();
  for (const p of program.violations) {
    const [x, y] = t.at(p, view);
    ctx.moveTo(x - 5, y - 5); ctx.lineTo(x + 5, y + 5); ctx.moveTo(x + 5, y - 5); ctx.lineTo(x - 5, y + 5);
  }
  ctx.stroke();
  ctx.restore();
}

// A check's report (path_m, violations[].point_m) to draw, or null to draw none.
export function showProgram(report) {
  if (!report || !Array.isArray(report.path_m)) {
    program = null;
  } else {
    const step = Math.max(1, Math.ceil(report.path_m.length / PROGRAM_POINTS));
    const path = report.path_m.filter((_, i) => i % step === 0 || i === report.path_m.length - 1);
    const violations = (report.violations || []).map((v) => v.point_m).filter(Array.isArray);
    program = { path, violations };
  }
  programVersion += 1;
  schedule();
}

function draw() {
  drawTimer = null;
  if (document.hidden) return; // drawn again on the next change once visible
  const key = JSON.stringify([seen, programVersion, views.top.section?.at_m, views.side.section?.at_m,
    Boolean(views.top.image), Boolean(views.side.image), views.top.error, views.side.error]);
  if (key === drawnKey) return;
  drawnKey = key;
  lastDraw = performance.now();
  drawView("top");
  drawView("side");
}

function schedule() {
  if (drawTimer !== null) return;
  drawTimer = setTimeout(draw, Math.max(0, lastDraw + MIN_FRAME_MS - performance.now()));
}

const rounded = (p) => (p ? p.map((v) => Math.round(v * 1e4) / 1e4) : null); // 0.1 mm

// Each /api/status: the measured point and the loop's goal; new sections when the cut moved.
export function onWorkspaceStatus(s) {
  const measured = s.ee.position_m, commanded = s.ee.commanded_m;
  const point = measured && measured.every((v) => v !== null) ? measured :
    commanded && commanded.every((v) => v !== null) ? commanded : null;
  seen.robot = rounded(point);
  const platform = s.ee.platform_m;
  seen.platform = hasTool() && platform && platform.every((v) => v !== null) ? rounded(platform) : null;
  seen.phi = currentPhiRad(s);
  const goal = s.goal.position_m;
  seen.goal = goal && goal.every((v) => v !== null) ? rounded(goal) : null;
  setText("ws-robot", seen.robot ? `${mmText(seen.robot)} mm` : "–");
  setText("ws-goal-now", seen.goal ? `${mmText(seen.goal)} mm` : "none");
  fetchSection(views.top);
  fetchSection(views.side);
  schedule();
}

// The Go-to form's values [m], a decimal comma read as a point; null unless all 3 are numbers.
function typedGoal() {
  const form = document.getElementById("goal-form");
  const values = ["x", "y", "z"].map((k) => {
    const text = String(form.elements[k]?.value ?? "").trim().replace(",", ".");
    return text === "" ? NaN : Number(text) / 1000;
  });
  return values.every(Number.isFinite) ? values : null;
}

// The typed goal's wrist angle [rad]: the form's φ [deg] (0 without a wrist), null when it
// is not a number.
function typedPhi() {
  if (!wrist.enabled) return 0;
  const text = String(document.getElementById("goal-form").elements.phi?.value ?? "").trim().replace(",", ".");
  const value = text === "" ? NaN : Number(text) * Math.PI / 180;
  return Number.isFinite(value) ? value : null;
}

async function checkTyped() {
  const goal = typedGoal();
  const phi = typedPhi();
  const ask = ++typedAsked;
  const button = document.getElementById("ws-go-nearest");
  if (!goal || phi === null || goal.some((v) => Math.abs(v) > 1)) {
    Object.assign(seen, { typed: null, inside: true, nearest: null });
    button.hidden = true;
    setText("ws-typed", goal ? "the typed goal is over 1 m away: not shown" : "–");
    schedule();
    return;
  }
  try {
    const [x, y, z] = goal.map(String);
    const query = new URLSearchParams({ x_m: x, y_m: y, z_m: z });
    if (wrist.enabled) query.set("phi_rad", phi.toFixed(6)); // the tip's region at its angle
    const answer = await get(`/api/workspace/nearest?${query}`);
    if (ask !== typedAsked) return; // the operator typed on meanwhile
    Object.assign(seen, {
      typed: rounded(goal), typedPhi: phi, inside: answer.inside, nearest: answer.nearest_m,
    });
    button.hidden = answer.inside;
    button.dataset.nearest = JSON.stringify(answer.nearest_m);
    setText("ws-typed", answer.inside ? `${mmText(goal)} mm: inside the workspace` :
      `${mmText(goal)} mm is outside; nearest reachable ${mmText(answer.nearest_m)} mm ` +
      `(${(answer.distance_m * 1000).toFixed(1)} mm away)`);
  } catch (err) {
    if (ask !== typedAsked) return;
    setText("ws-typed", `cannot check the typed goal: ${err.message}`);
    // the query workers were busy (503, Retry-After): ask again, as the operator would
    if (err.status === 503) typedTimer = setTimeout(checkTyped, BUSY_RETRY_MS);
  }
  schedule();
}

function typedChanged() {
  clearTimeout(typedTimer);
  typedTimer = setTimeout(checkTyped, TYPED_DEBOUNCE_MS);
}

// The nearest point, at the typed goal's angle (it was found for the tip at that angle),
// through Go to's checks: a long move or a large wrist turn asks first.
async function goNearest() {
  const nearest = JSON.parse(document.getElementById("ws-go-nearest").dataset.nearest || "null");
  if (!nearest) return;
  const phiDeg = wrist.enabled ? Math.round(seen.typedPhi * 1800 / Math.PI) / 10 : null;
  if (await goTo(nearest.map((v) => v * 1000), "Go to the nearest point", phiDeg)) {
    const form = document.getElementById("goal-form"); // the form now shows the goal sent
    ["x", "y", "z"].forEach((k, i) => { form.elements[k].value = (nearest[i] * 1000).toFixed(2); });
    checkTyped();
  }
}

// The Go-to form follows the robot (nothing typed): no typed goal to draw or check.
function typedFollows() {
  clearTimeout(typedTimer);
  typedAsked += 1; // an answer on its way is for an old value
  Object.assign(seen, { typed: null, inside: true, nearest: null });
  document.getElementById("ws-go-nearest").hidden = true;
  setText("ws-typed", "Go to shows where the robot is: type a goal to check it here");
  schedule();
}

export function startWorkspace2d() {
  const form = document.getElementById("goal-form");
  if (!form || !document.getElementById("ws-top")) return;
  form.addEventListener("input", typedChanged);
  form.addEventListener("change", typedChanged);
  form.addEventListener("follow", typedFollows);
  document.getElementById("ws-go-nearest").addEventListener("click", goNearest);
  document.addEventListener("visibilitychange", () => { if (!document.hidden) schedule(); });
  checkTyped();
  fetchSection(views.top);
  fetchSection(views.side);
}
