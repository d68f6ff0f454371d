// Entry point: read /api/info once, then start each part of the page.

import { get } from "./api.js";
import { startControl } from "./control.js";
import { startPlots } from "./plots.js";
import { onStatus, startRuns } from "./runs.js";
import { setStreamOnline, startStatus, state } from "./status.js";

// The viser scene is its own server on another port of the same host.
function embedScene(info) {
  const frame = document.getElementById("scene");
  const link = document.getElementById("scene-link");
  if (!info || info.viser_port === null || info.viser_port === undefined) {
    frame.hidden = true;
    link.hidden = true;
    document.getElementById("scene-off").hidden = info === null;
    return;
  }
  const url = `${location.protocol}//${location.hostname}:${info.viser_port}/`;
  frame.src = url;
  link.href = url;
}

async function boot() {
  let info = null;
  try {
    info = await get("/api/info");
  } catch {
    // offline at load: status polling shows the banner and keeps retrying
  }
  embedScene(info);
  startStatus();
  state.listeners.push(onStatus);
  startControl(info);
  startRuns();
  startPlots(setStreamOnline);
}

boot();
