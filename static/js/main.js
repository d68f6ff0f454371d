// Entry point: read /api/info once, then start each part of the page.

import { get } from "./api.js";
import { startControl } from "./control.js";
import { renderHealth } from "./health.js";
import { startPlotsFrame } from "./plotshost.js";
import { startPrograms } from "./programs.js";
import { onStatus, startRuns } from "./runs.js";
import { sceneStatus, startScene } from "./scene.js";
import { onServoStatus, startServoPanel } from "./servopanel.js";
import { startStatus, state } from "./status.js";
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
  state.listeners.push(renderHealth, onWorkspaceStatus, onServoStatus);
  startControl(info);
  startRuns();
  startPlotsFrame(info);
  startWorkspace2d();
  startPrograms();
  startServoPanel();
}

boot();
