// The e-stop keys and the e-stop request, shared by the page (control.js) and the plots'
// frame (plotsframe.js): whichever document has the keyboard focus stops the robot itself.

import { token } from "./api.js";

// True for a field where Space types a space (and so is no e-stop there).
export function typing(target) {
  return target instanceof HTMLInputElement && target.type !== "checkbox" ||
    target instanceof HTMLSelectElement || target instanceof HTMLTextAreaElement;
}

// The e-stop keys: Esc always, Space except while typing in a field.
export function isEstopKey(event) {
  return event.key === "Escape" || (event.key === " " && !typing(event.target));
}

// One press's id: every path a press takes carries it, and the server counts it once.
export function newPressId() {
  return `${Date.now().toString(36)}-${Math.random().toString(36).slice(2, 10)}`;
}

const ESTOP_OPTIONS = { method: "POST", keepalive: true, priority: "high" };

// POST /api/estop of this document's server: its own keepalive fetch at high priority, no
// lease and no token prompt (the route needs neither), nothing awaited before it.
export function postEstop(press) {
  const headers = token() ? { Authorization: `Bearer ${token()}` } : {};
  return fetch(`/api/estop?press=${press}`, { ...ESTOP_OPTIONS, headers });
}

// POST to the server's e-stop listener (its own port and thread): no headers, so a plain
// cross-origin POST with no preflight round trip.
export function postListener(url, press) {
  return fetch(`${url}?press=${press}`, { ...ESTOP_OPTIONS, mode: "cors" });
}
