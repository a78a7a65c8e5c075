// api.js — the only place that talks HTTP. Adds the bearer token the operator
// typed (kept in sessionStorage: it lives as long as the tab, never on disk
// across browser restarts), turns error bodies into exceptions, and builds the
// socket URLs (browsers cannot set headers on a WebSocket, so the token goes
// in the `token` query parameter the server accepts for that reason).

const TOKEN_KEY = "navguard.token";

let token = "";
try { token = sessionStorage.getItem(TOKEN_KEY) || ""; } catch (_) { /* storage disabled */ }

/** Listeners told when the server wants a (new) token. */
const authListeners = new Set();
/** Listeners told whether the server answered at all. */
const reachListeners = new Set();

export function onAuthNeeded(fn) { authListeners.add(fn); }
export function onReachability(fn) { reachListeners.add(fn); }

export function hasToken() { return token !== ""; }

export function setToken(value) {
  token = value;
  try { sessionStorage.setItem(TOKEN_KEY, value); } catch (_) { /* storage disabled */ }
}

/** The server refused our token (401). */
export class AuthError extends Error {}
/** The server could not be reached. */
export class NetError extends Error {}
/** The server answered with an error status; `status` and `code` say which. */
export class HttpError extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }
}

/**
 * `request("GET", "api/v1/sessions")` → parsed JSON (null for 204).
 * Paths are relative so the page also works behind a path prefix. `extra` adds
 * headers (the reason of a change, `X-Navguard-Reason`, for the audit log).
 */
export async function request(method, path, body, extra) {
  const headers = { Accept: "application/json", ...(extra || {}) };
  if (token) headers.Authorization = "Bearer " + token;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  let res;
  try {
    res = await fetch(new URL(path, document.baseURI), {
      method, headers, cache: "no-store",
      body: body === undefined ? undefined : JSON.stringify(body),
    });
  } catch (e) {
    for (const fn of reachListeners) fn(false);
    throw new NetError(String((e && e.message) || e));
  }
  for (const fn of reachListeners) fn(true);
  if (res.status === 401) {
    for (const fn of authListeners) fn(token !== "");
    throw new AuthError("the server needs a valid token");
  }
  if (res.status === 204) return null;
  let data = null;
  try { data = await res.json(); } catch (_) { /* not JSON */ }
  if (!res.ok) {
    const err = data && data.error;
    throw new HttpError(res.status, err && err.code, (err && err.message) || "HTTP " + res.status);
  }
  return data;
}

export const get = (path) => request("GET", path);

/**
 * The token's name and scopes (`GET api/v1/whoami`); null from a server without
 * that route (which has no scopes: everything is allowed).
 */
export async function whoami() {
  try {
    return await get("api/v1/whoami");
  } catch (e) {
    if (e instanceof HttpError && e.status === 404) return null;
    throw e;
  }
}

/** ws(s)://…/path?token=… for a socket route. */
export function socketUrl(path) {
  const url = new URL(path, document.baseURI);
  url.protocol = location.protocol === "https:" ? "wss:" : "ws:";
  if (token) url.searchParams.set("token", token);
  return url.href;
}

/**
 * Downloads `path` (with the token, which a plain link could not carry) and saves it
 * as `filename` through a temporary object URL.
 */
export async function download(path, filename) {
  const headers = {};
  if (token) headers.Authorization = "Bearer " + token;
  const res = await fetch(new URL(path, document.baseURI), { headers, cache: "no-store" });
  if (res.status === 401) {
    for (const fn of authListeners) fn(token !== "");
    throw new AuthError("the server needs a valid token");
  }
  if (!res.ok) {
    let message = "HTTP " + res.status;
    try { const data = await res.json(); if (data && data.error) message = data.error.message; } catch (_) { /* not JSON */ }
    throw new HttpError(res.status, null, message);
  }
  const url = URL.createObjectURL(await res.blob());
  const a = document.createElement("a");
  a.href = url;
  a.download = filename;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}
