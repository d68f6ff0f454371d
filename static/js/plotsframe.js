// The tracking plots' own document (plots.html), loaded by the page in a frame from the other
// loopback name so that they run on another renderer main thread than the page's e-stop key
// (isolation.js; the messages are listed in plotshost.js). Opened on its own it works too:
// it then reads /api/info itself and has no page to tell.

import { get, setToken } from "./api.js";
import { isEstopKey, newPressId, postEstop } from "./estopkey.js";
import { liveAgain, replayRun, startPlots } from "./plots.js";
import { setWrist, wrist } from "./wrist.js";

const MESSAGE_TYPE = "deltadash-plots";
const framed = window.parent !== window;
// the page's origin, given in the address (postMessage needs it): nothing is sent elsewhere
const parentOrigin = new URLSearchParams(location.search).get("parent");
let tokenWaiter = null;

function tell(body) {
  if (framed && parentOrigin) window.parent.postMessage({ kind: MESSAGE_TYPE, ...body }, parentOrigin);
}

// The telemetry stream wants the token: the page has it (or asks the operator once).
function askToken(reason, sent) {
  if (!framed) return null; // plots.js then prompts itself
  tell({ type: "token", sent });
  return new Promise((resolve) => { tokenWaiter = resolve; });
}

// Space / Esc while this frame has the focus (after a click on its tools or a drag-zoom):
// stop first, from here, then tell the page (which records the press, says so and sends it
// by its other paths too).
function onKey(event) {
  if (!isEstopKey(event)) return;
  event.preventDefault();
  event.stopImmediatePropagation();
  if (event.repeat) return;
  const press = newPressId();
  postEstop(press).catch(() => {}); // the page reports whether the press was confirmed
  tell({
    type: "estop", press, source: event.type,
    event_unix_ms: performance.timeOrigin + event.timeStamp, sent_unix_ms: Date.now(),
  });
}

let started = false;
let pendingReplay = null; // a replay asked for before the plots started

function start(wristInfo) {
  if (started) return;
  started = true;
  setWrist(wristInfo);
  document.querySelectorAll("[data-wrist]").forEach((el) => { el.hidden = !wrist.enabled; });
  startPlots((online) => tell({ type: "stream", online }), framed ? askToken : null);
  const asked = pendingReplay || new URLSearchParams(location.search).get("replay");
  if (asked) replay(asked);
}

async function replay(runId) {
  if (!started) {
    pendingReplay = runId;
    return;
  }
  const ok = await replayRun(runId);
  tell({ type: "replayed", run_id: runId, ok });
}

window.addEventListener("keydown", onKey, { capture: true });
if (framed) {
  window.addEventListener("message", (event) => {
    if (event.source !== window.parent || event.origin !== parentOrigin) return;
    const data = event.data || {};
    if (data.kind !== MESSAGE_TYPE) return;
    if (data.type === "info") start(data.wrist);
    else if (data.type === "replay" && typeof data.run_id === "string") replay(data.run_id);
    else if (data.type === "live") liveAgain();
    else if (data.type === "token" && data.token) {
      setToken(data.token); // this frame's origin has its own storage
      if (tokenWaiter) tokenWaiter(true);
      tokenWaiter = null;
    }
  });
  new ResizeObserver(() => tell({ type: "height", px: document.documentElement.scrollHeight }))
    .observe(document.body);
  tell({ type: "ready" });
} else {
  get("/api/info").then((info) => start(info.wrist), () => start(null));
}
