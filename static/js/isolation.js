// Where a heavy part of the page runs so that it cannot hold up the e-stop key.
//
// Chromium runs a page and its frames from the same *site* (scheme and host: the port does
// not count) on one renderer main thread, the thread where Space and Esc are handled. The
// 3D scene (viser, software WebGL without a GPU) and the tracking plots (plotly: SVG redrawn
// 10-30 times a second, 85 % of that thread during a run on a 2-core machine) are therefore
// loaded from the same machine under its other loopback name, another site, which site
// isolation (on by default in desktop chromium and Chrome) gives its own renderer process.

// The same machine under another site's name, or null when there is none the page can know
// (opened under a network name or address).
export function isolatedHost(hostname) {
  if (hostname === "127.0.0.1" || hostname === "[::1]") return "localhost";
  if (hostname === "localhost") return "127.0.0.1";
  return null;
}

// The origin ("http://name:port") under which a part served on ``port`` is loaded: the other
// site where there is one, else this page's own host name.
export function isolatedOrigin(port) {
  const host = isolatedHost(location.hostname) || location.hostname;
  return `${location.protocol}//${host}${port ? `:${port}` : ""}`;
}
