// Entry point: read /api/info once, then start each part of the page.

import { get } from "./api.js";
import { startCalibration } from "./calibration.js";
import { startControl } from "./control.js";
import { onContactStatus, startContact } from "./contact.js";
import { startHold } from "./hold.js";
import { renderHealth } from "./health.js";
import { startPlotsFrame } from "./plotshost.js";
import { startProgramControl } from "./programcontrol.js";
import { startPrograms } from "./programs.js";
import { startReportViews } from "./report.js";
import { onStatus, startRuns } from "./runs.js";
import { sceneStatus, startScene } from "./scene.js";
import { onServoStatus, startServoPanel } from "./servopanel.js";
import { startStatus, state } from "./status.js";
import { startTuning } from "./tuning.js";
import { onWorkspaceStatus, startWorkspace2d } from "./workspace2d.js";
import { renderWrist, startWrist } from "./wrist.js";

async function boot() {
  let info = null;
  try {
    info = await get("/api/info");
  } catch {
    // offline at load: status polling shows the banner and keeps retrying
  }
  startWrist(info); // first: what the other parts show depends on whether a wrist is fitted
  startScene(info);
  startStatus();
  state.listeners.push(onStatus, renderWrist, sceneStatus);
  state.listeners.push(renderHealth, onWorkspaceStatus, onServoStatus, onContactStatus);
  startControl(info);
  startRuns();
  startPlotsFrame(info);
  startReportViews();
  startWorkspace2d();
  startPrograms();
  startProgramControl();
  startServoPanel();
  startCalibration();
  startTuning();
  startHold();
  startContact();
}

boot();
