// The page's side of the tracking plots, which run in their own frame (plots.html, from the
// other loopback name: its own renderer process, isolation.js) so that plotly's drawing never
// holds up this page's e-stop key. The frame talks to the page by postMessage only:
//   frame -> page: {type: "ready"}, {type: "height", px}, {type: "stream", online},
//                  {type: "estop", press, event_unix_ms, sent_unix_ms, source} (a key pressed
//                  while the frame had the focus; the frame sent POST /api/estop itself),
//                  {type: "token", sent} (its telemetry stream was refused: it wants the token)
//                  {type: "replayed", run_id, ok} (a replay asked for is shown, or why not)
//   page -> frame: {type: "info", wrist: {enabled, min_rad, max_rad}}, {type: "token", token},
//                  {type: "replay", run_id} (show a recorded run in the plots), {type: "live"}

import { promptToken, token } from "./api.js";
import { estop } from "./control.js";
import { isolatedOrigin } from "./isolation.js";
import { setStreamOnline } from "./status.js";

const MESSAGE_TYPE = "deltadash-plots";

let sendToFrame = null;

// Replay the recorded run ``runId`` in the tracking plots (scrolled into view); the plots'
// "Live" button goes back.
export function replayInPlots(runId) {
  if (!sendToFrame) return false;
  sendToFrame({ type: "replay", run_id: runId });
  document.getElementById("plots-frame").scrollIntoView({ block: "nearest" });
  return true;
}

export function startPlotsFrame(info) {
  const frame = document.getElementById("plots-frame");
  const origin = isolatedOrigin(location.port);
  const send = (body) => frame.contentWindow?.postMessage({ kind: MESSAGE_TYPE, ...body }, origin);
  sendToFrame = send;
  window.addEventListener("message", async (event) => {
    if (event.origin !== origin || event.source !== frame.contentWindow) return;
    const data = event.data || {};
    if (data.kind !== MESSAGE_TYPE) return;
    if (data.type === "estop") estop(null, data);
    else if (data.type === "height") frame.style.height = `${Math.ceil(data.px)}px`;
    else if (data.type === "stream") setStreamOnline(Boolean(data.online));
    else if (data.type === "ready") send({ type: "info", wrist: (info && info.wrist) || null });
    else if (data.type === "token") {
      if (token() && token() !== data.sent) send({ type: "token", token: token() });
      else if (await promptToken("The telemetry stream requires a token.", data.sent)) {
        send({ type: "token", token: token() });
      }
    }
  });
  // Keys go to the frame that has focus: once the pointer leaves the plots, this page takes
  // the focus back (the frame's own keys e-stop too, meanwhile).
  frame.addEventListener("mouseleave", () => window.focus());
  const parent = encodeURIComponent(location.origin);
  frame.src = `${origin}/plots.html?parent=${parent}`;
}
