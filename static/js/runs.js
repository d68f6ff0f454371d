// The runs table and comparing runs; the test-run form (preview, start, abort, progress) is
// static/js/testruns.js. The running run comes from the server (GET /api/runs: its progress
// and parameters), so a page reloaded mid-run, or another tab, shows where the run really is.

import { get, getBlob, mm, fixed } from "./api.js";
import { escape } from "./status.js";
import { followRun, onRunStatus, startTestRuns } from "./testruns.js";
import { showError, setText } from "./ui.js";

const RUNS_POLL_MS = 2000;
export const onStatus = onRunStatus; // the form's progress and preview follow each status
const picked = new Set(); // run ids ticked for comparing
let compareUrl = null; // the object URL of the shown comparison plot

const triple = (t, key) => (t ? ["x", "y", "z"].map((a) => mm(t[a]?.[key], 2)).join(" / ") : "–");

// The loop's health during the run as a coloured flag; the reasons (or the figures) as its
// tooltip, so the row stays narrow.
function health(run) {
  const h = run.stats && run.stats.health;
  if (!h || typeof h.ok !== "boolean") {
    return `<td class="health"><span class="flag none" title="not checked (a run from before health was kept)">–</span></td>`;
  }
  const figures = [
    typeof h.rate_hz === "number" ? `${fixed(h.rate_hz, 0)} Hz` : null,
    h.lateness_ms && typeof h.lateness_ms.p99 === "number" ? `p99 lateness ${fixed(h.lateness_ms.p99, 1)} ms` : null,
    typeof h.overruns === "number" ? `${h.overruns} overruns` : null,
  ].filter(Boolean).join(", ");
  if (h.ok) return `<td class="health"><span class="flag ok" title="loop healthy: ${escape(figures)}">ok</span></td>`;
  const why = (h.reasons || []).join("; ") || "not healthy";
  return `<td class="health"><span class="flag bad" title="loop NOT HEALTHY: ${escape(why)}"` +
    ` aria-label="loop not healthy: ${escape(why)}">flagged</span></td>`;
}

function runRow(run) {
  // a hold run is judged in the world frame (thesis Table 6.3), the others by tracking
  const t = run.stats && (run.stats.world || run.stats.tracking);
  const under = t ? ["x", "y", "z"].map((a) => `${fixed(100 * t[a].share_under_1mm, 0)}%`).join(" / ") : "–";
  const base = `/api/runs/${encodeURIComponent(run.run_id)}`;
  const links = [["report.png", "report"], ["report.pdf", "PDF"], ["log.mcap", "MCAP"], ["log.csv", "CSV"]]
    .filter(([name]) => !name.startsWith("report") || run.has_report)
    .map(([name, label]) => `<a href="${base}/${name}" target="_blank" rel="noopener"` +
      `${name === "report.png" ? ` class="report" data-run="${escape(run.run_id)}"` : ""}>${label}</a>`)
    .join(" ");
  const reason = run.reason ? ` title="${escape(run.reason)}"` : ""; // long reasons as a tooltip
  const id = escape(run.run_id);
  const pick = `<input type="checkbox" class="pick" value="${id}" aria-label="compare run ${id}"` +
    `${picked.has(run.run_id) ? " checked" : ""}${run.state === "running" ? " disabled" : ""}>`;
  // the id may wrap after its date (a narrow table fits 1280 px)
  const shownId = escape(run.run_id).replace(/^(\d{8}-)/, "$1<wbr>");
  return `<tr data-run="${id}"><td>${pick}</td><td>${shownId}</td>` +
    `<td title="${escape(run.description || "")}">${escape(run.kind)}${run.stats && run.stats.world ? " (world)" : ""}</td>` +
    `<td class="${run.state === "done" ? "ok" : run.state === "running" ? "" : "bad"}"${reason}>${escape(run.state)}</td>` +
    health(run) +
    `<td class="num">${triple(t, "rmse_m")}</td><td class="num">${triple(t, "max_abs_m")}</td>` +
    `<td class="num">${under}</td><td class="files">${links}</td></tr>`;
}

export async function refreshRuns() {
  try {
    const runs = await get("/api/runs");
    const html = runs.map(runRow).join("") || `<tr><td colspan="9" class="muted">no runs yet</td></tr>`;
    const body = document.getElementById("run-rows");
    if (body.innerHTML !== html) body.innerHTML = html;
    // a run started anywhere (this tab before a reload, the CLI, the 3D scene, another tab)
    // is followed from the server's record: its progress and parameters
    followRun(runs.find((r) => r.state === "running") || null);
    const known = new Set(runs.map((r) => r.run_id));
    for (const id of picked) if (!known.has(id)) picked.delete(id);
    updateCompareButton();
  } catch {
    // the status poll shows the connection banner; keep the last table
  }
}

// Comparing runs: tick two or more rows, then GET /api/runs/compare (the table) and its PNG.
function updateCompareButton() {
  document.getElementById("compare-runs").disabled = picked.size < 2;
  setText("compare-count", picked.size ? `${picked.size} selected` : "");
}

function onPick(event) {
  const box = event.target;
  if (!box.classList.contains("pick")) return;
  if (box.checked) picked.add(box.value);
  else picked.delete(box.value);
  updateCompareButton();
}

function cell(value, unit) {
  if (value === null || value === undefined) return `<td class="num muted">–</td>`;
  if (typeof value === "string") return `<td class="${value.startsWith("NOT") ? "bad" : ""}">${escape(value)}</td>`;
  const digits = unit === "mm" ? 2 : ["%", "ticks", ""].includes(unit) ? 0 : 1;
  return `<td class="num">${fixed(value, digits)}</td>`;
}

async function compare() {
  const query = new URLSearchParams({ ids: [...picked].join(",") });
  try {
    const result = await get(`/api/runs/compare?${query}`);
    const head = `<tr><th scope="col"></th>${result.ids.map((id) => `<th scope="col">${escape(id)}</th>`).join("")}</tr>`;
    const rows = result.rows.map((row) =>
      `<tr><th scope="row">${escape(row.label)}${row.unit ? ` [${escape(row.unit)}]` : ""}</th>` +
      `${row.values.map((v) => cell(v, row.unit)).join("")}</tr>`).join("");
    document.getElementById("compare-table").innerHTML = `<thead>${head}</thead><tbody>${rows}</tbody>`;
    document.getElementById("compare").hidden = false;
    const plot = document.getElementById("compare-plot");
    if (compareUrl) URL.revokeObjectURL(compareUrl);
    compareUrl = URL.createObjectURL(await getBlob(result.plot));
    plot.dataset.ids = result.ids.join(",");
    plot.src = compareUrl;
  } catch (err) {
    showError(err);
  }
}

// A run's report in the page (a lightbox), not a download or a new tab; a modified or
// middle click still opens the link as the browser would. Esc closes it (Esc is also the
// e-stop key everywhere on the page: that stays so), as do a click outside it and Close.
function openReport(event) {
  const link = event.target.closest("a.report");
  if (!link || event.button !== 0 || event.ctrlKey || event.metaKey || event.shiftKey || event.altKey) return;
  event.preventDefault();
  const box = document.getElementById("report-box");
  const img = document.getElementById("report-img");
  img.src = link.href;
  img.alt = `the report of run ${link.dataset.run}`;
  setText("report-title", `Report of run ${link.dataset.run}`);
  document.getElementById("report-open").href = link.href;
  if (!box.open) box.showModal();
}

function startReportBox() {
  const box = document.getElementById("report-box");
  document.getElementById("run-rows").addEventListener("click", openReport);
  document.getElementById("report-close").addEventListener("click", () => box.close());
  box.addEventListener("click", (event) => { if (event.target === box) box.close(); }); // the backdrop
  // Esc: the e-stop handler takes the key (and cancels the dialog's own Esc); close it here,
  // never stopping the key from reaching the e-stop
  document.addEventListener("keydown", (event) => { if (event.key === "Escape" && box.open) box.close(); });
  box.addEventListener("close", () => { document.getElementById("report-img").removeAttribute("src"); });
}

function closeCompare() {
  document.getElementById("compare").hidden = true;
}

export function startRuns() {
  startTestRuns(refreshRuns);
  document.getElementById("run-rows").addEventListener("change", onPick);
  document.getElementById("compare-runs").addEventListener("click", compare);
  document.getElementById("compare-close").addEventListener("click", closeCompare);
  startReportBox();
  refreshRuns();
  setInterval(refreshRuns, RUNS_POLL_MS);
}
