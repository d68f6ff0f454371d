// The viser 3D scene, embedded in a frame or opened in its own tab (it runs on its own port).
// The frame comes from the other loopback name, so it runs in another renderer process than
// this page (isolation.js). Without a GPU its software WebGL still takes CPU that this page's
// e-stop key needs (and shares its process with the plots'), so the frame is on by default
// only with hardware rendering, and without one it draws at half resolution and pauses
// while the arm moves; the operator's choice is remembered per browser.

import { armMoving } from "./control.js";
import { isolatedOrigin } from "./isolation.js";

const CHOICE_KEY = "deltadash.sceneEmbed";
const SOFTWARE_DPR = 0.5;
// Without a GPU the embedded scene's drawing is paused while the arm moves (the issue's
// "scene rendering paused while the operator controls"): on a 2-core machine it and the
// plots took the CPU that the page's e-stop key needs (docs/dashboard.md "The e-stop"). A
// hidden frame of another site draws nothing in chromium. It goes on once the arm has
// rested for RESUME_AFTER_MS.
const RESUME_AFTER_MS = 1000;
let pauseWhileMoving = false; // embedded under software WebGL
let stillSince = null; // since when the arm rests [performance.now() ms], null: it moves

// True when WebGL runs on the CPU (SwiftShader, llvmpipe, software rasterisers).
function softwareWebGL() {
  try {
    const gl = document.createElement("canvas").getContext("webgl");
    if (!gl) return true;
    const ext = gl.getExtension("WEBGL_debug_renderer_info");
    const renderer = String(gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    gl.getExtension("WEBGL_lose_context")?.loseContext();
    return /swiftshader|llvmpipe|software|softpipe/i.test(renderer);
  } catch {
    return true;
  }
}

// status.js hands every status here (every 200 ms).
export function sceneStatus(s) {
  const frame = document.getElementById("scene");
  const moving = pauseWhileMoving && !frame.hidden && armMoving(s);
  const now = performance.now();
  if (moving) stillSince = null;
  else if (stillSince === null) stillSince = now;
  const pause = moving || (stillSince !== null && now - stillSince < RESUME_AFTER_MS &&
    frame.classList.contains("paused"));
  frame.classList.toggle("paused", pause);
  document.getElementById("scene-paused").hidden = !pause;
}

function show(url, embed) {
  const frame = document.getElementById("scene");
  const note = document.getElementById("scene-note");
  frame.hidden = !embed;
  note.hidden = embed;
  if (embed && frame.getAttribute("src") !== url) frame.src = url;
  if (!embed) {
    frame.removeAttribute("src"); // unload: a hidden viser still renders
    note.textContent = "The 3D scene is not shown here (tick “show here”, or open it in a new tab).";
  }
}

export function startScene(info) {
  const link = document.getElementById("scene-link");
  const toggle = document.getElementById("scene-embed");
  const note = document.getElementById("scene-note");
  if (!info || info.viser_port === null || info.viser_port === undefined) {
    link.hidden = true;
    toggle.parentElement.hidden = true;
    note.hidden = info === null;
    note.textContent = "The 3D scene is turned off on this server (server.scene = false).";
    return;
  }
  const url = `${location.protocol}//${location.hostname}:${info.viser_port}/`;
  // Without a GPU every pixel of the scene is drawn by the CPU that also runs this page's
  // e-stop key: the embedded scene draws at half resolution there (a quarter of the pixels;
  // viser's own fixedDpr setting). The tab of "open in a new tab" keeps full resolution.
  const software = softwareWebGL();
  pauseWhileMoving = software;
  const frameBase = `${isolatedOrigin(info.viser_port)}/`; // its own process (isolation.js)
  const frameUrl = software ? `${frameBase}?fixedDpr=${SOFTWARE_DPR}` : frameBase;
  link.href = url;
  const saved = localStorage.getItem(CHOICE_KEY);
  toggle.checked = saved === null ? !software : saved === "1";
  toggle.addEventListener("change", () => {
    localStorage.setItem(CHOICE_KEY, toggle.checked ? "1" : "0");
    show(frameUrl, toggle.checked);
  });
  show(frameUrl, toggle.checked);
  // Keys go to the frame that has focus: once the pointer leaves the scene, focus comes back
  // to this page, where Space and Esc are the e-stop.
  document.getElementById("scene").addEventListener("mouseleave", () => window.focus());
  if (!toggle.checked && saved === null) {
    note.textContent = "This browser renders WebGL in software: the 3D scene would slow the plots, " +
      "so it is not shown here. Tick “show here” to embed it anyway, or open it in a new tab.";
  }
}
