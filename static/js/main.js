// Entry point: read /api/info once, then start each part of the page.

import { get } from "./api.js";
import { startControl } from "./control.js";
import { startPlots } from "./plots.js";
import { onStatus, startRuns } from "./runs.js";
import { startScene } from "./scene.js";
import { setStreamOnline, startStatus, state } from "./status.js";

async function boot() {
  let info = null;
  try {
    info = await get("/api/info");
  } catch {
    // offline at load: status polling shows the banner and keeps retrying
  }
  startScene(info);
  startStatus();
  state.listeners.push(onStatus);
  startControl(info);
  startRuns();
  startPlots(setStreamOnline);
}

boot();
