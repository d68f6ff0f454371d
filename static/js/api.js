// The one place the page talks HTTP to the server: token, client name, errors as messages.
// Only the public API is used (docs/server.md); everything is SI there, mm/deg on the page.

const TOKEN_KEY = "deltadash.token";
const CLIENT_KEY = "deltadash.client";

// The name this tab shows as the lease holder (GET /api/lease): a label, not authority.
export function clientName() {
  let name = sessionStorage.getItem(CLIENT_KEY);
  if (!name) {
    name = "dashboard-" + Math.random().toString(36).slice(2, 8);
    sessionStorage.setItem(CLIENT_KEY, name);
  }
  return name;
}

// A frame from another site may be refused storage (chromium blocks third-party storage
// where it blocks third-party cookies): the plots' frame then keeps its token in memory.
let memoryToken = null;

export function token() {
  try {
    return sessionStorage.getItem(TOKEN_KEY);
  } catch {
    return memoryToken;
  }
}

// Keep ``value`` as this tab's token (the plots' frame is given the page's).
export function setToken(value) {
  memoryToken = value;
  try {
    sessionStorage.setItem(TOKEN_KEY, value);
  } catch {
    // refused storage: memoryToken serves
  }
}

export class ApiError extends Error {
  // ``body``: the answer's whole JSON (e.g. a program's 422: line, word, violations), or null
  constructor(status, detail, body = null) {
    super(detail);
    this.status = status;
    this.body = body;
  }
}

let tokenPrompt = null; // a single prompt even when several requests fail at once

// Ask once for the token; stored per tab (sessionStorage) so it is gone when the tab is.
// ``sent``: the token the refused request carried; when another request's prompt has set a
// different one since (several reads are refused at once on a networked server), no prompt.
export function promptToken(reason, sent = null) {
  if (token() && token() !== sent) return Promise.resolve(true);
  if (!tokenPrompt) {
    tokenPrompt = Promise.resolve().then(() => {
      const value = window.prompt(`${reason}\nServer token:`, "");
      if (value) setToken(value.trim());
      tokenPrompt = null;
      return Boolean(value);
    });
  }
  return tokenPrompt;
}

async function failure(response) {
  try {
    const body = await response.json();
    const detail = typeof body.detail === "string" ? body.detail : JSON.stringify(body.detail);
    return new ApiError(response.status, detail, body);
  } catch {
    return new ApiError(response.status, response.statusText || `HTTP ${response.status}`);
  }
}

// JSON request; a 401 asks for the token and retries once. Throws ApiError with the detail.
export async function request(method, path, body, retried = false) {
  const headers = {};
  const sent = token();
  if (body !== undefined) headers["Content-Type"] = "application/json";
  if (sent) headers.Authorization = `Bearer ${sent}`;
  if (leaseId) headers["X-Lease"] = leaseId;
  const response = await fetch(path, {
    method, headers, body: body === undefined ? undefined : JSON.stringify(body),
  });
  if (response.status === 401 && !retried) {
    if (await promptToken("This server requires a token.", sent)) {
      return request(method, path, body, true);
    }
  }
  if (!response.ok) throw await failure(response);
  return response.json();
}

export const get = (path) => request("GET", path);

// A file (e.g. a PNG) with the token: an <img src> could not send it. Throws ApiError.
export async function getBlob(path) {
  const headers = token() ? { Authorization: `Bearer ${token()}` } : {};
  const response = await fetch(path, { headers });
  if (!response.ok) throw await failure(response);
  return response.blob();
}
export const post = (path, body) => request("POST", path, body);

// This tab's control lease: the secret id from POST /api/lease, in memory only (a reload or
// another tab is another client). Sent as X-Lease with every request.
let leaseId = null;

export async function takeLease(takeOver = false) {
  const lease = await post("/api/lease", { client: clientName(), take_over: takeOver });
  leaseId = lease.lease_id;
  return lease;
}

const heldByAnother = (err) => err.status === 409 && err.message.includes("control is held by");

// A command that moves the robot or changes its power: takes the lease on first use, and once
// more when the server no longer knows ours (restarted, lapsed and released). When another
// client holds control it throws the 409 "control is held by ..." (see control.js's command).
// Commands sent together before the tab holds control (a double click) wait for one take:
// a second take would be refused as control held by this very tab.
let taking = null;

function takeOnce() {
  if (!taking) taking = takeLease(false).finally(() => { taking = null; });
  return taking;
}

export async function postControl(path, body) {
  if (!leaseId) await takeOnce();
  try {
    return await post(path, body);
  } catch (err) {
    if (err.status !== 409 || heldByAnother(err) || !err.message.includes("/api/lease")) throw err;
    leaseId = null;
    await takeOnce();
    return post(path, body);
  }
}

export function telemetryUrl(hz) {
  const proto = location.protocol === "https:" ? "wss:" : "ws:";
  const query = new URLSearchParams({ hz: String(hz) });
  if (token()) query.set("token", token());
  return `${proto}//${location.host}/api/telemetry?${query}`;
}

// SI -> display units.
export const mm = (m, digits = 1) => (m === null || m === undefined ? "–" : (m * 1000).toFixed(digits));
export const deg = (rad, digits = 1) => (rad === null || rad === undefined ? "–" : (rad * 180 / Math.PI).toFixed(digits));
export const fixed = (v, digits = 2) => (v === null || v === undefined ? "–" : Number(v).toFixed(digits));
