// The viser 3D scene, embedded in a frame or opened in its own tab (it runs on its own port).
// A same-site frame shares this page's main thread: without a GPU, viser's software WebGL
// took it over and the plots fell below 1 frame/s. So the frame is on by default only with
// hardware rendering; the operator's choice is remembered per browser.

const CHOICE_KEY = "deltadash.sceneEmbed";

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

// The same machine under another site's name: a frame from another site gets its own
// renderer process (chromium's site isolation), so viser's drawing cannot hold up this page's
// main thread, where the e-stop key is handled. A port alone does not make another site.
export function isolatedHost(hostname) {
  if (hostname === "127.0.0.1" || hostname === "[::1]") return "localhost";
  if (hostname === "localhost") return "127.0.0.1";
  return null;
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
  const isolated = isolatedHost(location.hostname);
  const frameUrl = isolated ? `${location.protocol}//${isolated}:${info.viser_port}/` : url;
  link.href = url;
  const saved = localStorage.getItem(CHOICE_KEY);
  toggle.checked = saved === null ? !softwareWebGL() : saved === "1";
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
