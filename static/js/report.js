// The report lightbox's other views (index.html's <dialog id="report-box">, opened by
// runs.js with the report's PNG): "Interactive" shows the same run as plotly plots
// (report.html, static/js/plotsreport.js) in a frame from the other loopback name, so that
// its drawing never holds up this page's e-stop key; "Replay in the plots" shows the run's
// recorded signals in the tracking plots (plotshost.js). Messages with the frame are
// listed in plotsreport.js.

import { token } from "./api.js";
import { estop } from "./control.js";
import { isolatedOrigin } from "./isolation.js";
import { replayInPlots } from "./plotshost.js";

const MESSAGE_TYPE = "deltadash-report";

// The run whose report the lightbox shows (from the PNG's address), or null.
function shownRun() {
  const src = document.getElementById("report-img").getAttribute("src") || "";
  const match = src.match(/\/api\/runs\/([^/?#]+)\/report\.png/);
  return match ? decodeURIComponent(match[1]) : null;
}

export function startReportViews() {
  const box = document.getElementById("report-box");
  const img = document.getElementById("report-img");
  const frame = document.getElementById("report-frame");
  const button = document.getElementById("report-interactive");
  const origin = isolatedOrigin(location.port);

  function showImage() {
    frame.hidden = true;
    frame.removeAttribute("src"); // its plots go with it
    img.hidden = false;
    button.textContent = "Interactive";
    button.setAttribute("aria-pressed", "false");
  }

  function showInteractive() {
    const runId = shownRun();
    if (!runId) return;
    const parent = encodeURIComponent(location.origin);
    frame.src = `${origin}/report.html?parent=${parent}&run=${encodeURIComponent(runId)}`;
    frame.title = `interactive report of run ${runId}`;
    frame.hidden = false;
    img.hidden = true;
    button.textContent = "Image";
    button.setAttribute("aria-pressed", "true");
  }

  // the lightbox shows other images too (calibration, tuning): the run's views only for a run
  const replayButton = document.getElementById("report-replay");
  const offerViews = () => {
    const run = shownRun() !== null;
    button.hidden = !run && frame.hidden;
    replayButton.hidden = !run;
  };
  new MutationObserver(offerViews).observe(img, { attributes: true, attributeFilter: ["src"] });
  offerViews();
  button.addEventListener("click", () => (frame.hidden ? showInteractive() : showImage()));
  replayButton.addEventListener("click", () => {
    const runId = shownRun();
    if (!runId) return;
    box.close();
    replayInPlots(runId);
  });
  box.addEventListener("close", showImage);
  window.addEventListener("message", (event) => {
    if (event.origin !== origin || event.source !== frame.contentWindow) return;
    const data = event.data || {};
    if (data.kind !== MESSAGE_TYPE) return;
    if (data.type === "ready") frame.contentWindow.postMessage({ kind: MESSAGE_TYPE, type: "token", token: token() }, origin);
    else if (data.type === "estop") estop(null, data);
  });
}
