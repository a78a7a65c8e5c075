// main.js — wires the page: hash routing between the five views, the status
// line, the token prompt, and one requestAnimationFrame loop that renders the
// visible view at most once per frame however many messages arrived (20
// stats messages a second from each session would otherwise each cost a
// layout). The loop times itself; `window.navguardPerf()` reports it.

import { onAuthNeeded, onReachability, setToken, whoami } from "./api.js";
import { Live } from "./live.js";
import { OverviewView } from "./overview.js";
import { SessionView } from "./session.js";
import { AlarmsView } from "./alarms.js";
import { ModelsView } from "./models.js";
import { AuditView } from "./audit.js";
import { fmtClock } from "./dom.js";

const $ = (id) => document.getElementById(id);
const live = new Live();
const views = {
  overview: new OverviewView(live, $("view-overview")),
  session: new SessionView(live, $("view-session")),
  alarms: new AlarmsView(live, $("view-alarms")),
  models: new ModelsView($("view-models")),
  audit: new AuditView($("view-audit")),
};
let current = null;

// ------------------------------------------------------------------ routing

function route() {
  const hash = location.hash.replace(/^#\/?/, "");
  const [name, ...rest] = hash.split("/");
  const next = views[name] ? name : hash.startsWith("session/") ? "session" : "overview";
  if (current === "models" && next !== "models") views.models.close();
  current = next;
  for (const [k] of Object.entries(views)) $("view-" + k).hidden = k !== next;
  for (const a of document.querySelectorAll("nav a")) {
    if (a.dataset.view === next) a.setAttribute("aria-current", "page"); else a.removeAttribute("aria-current");
  }
  if (next === "session") views.session.open(decodeURIComponent(rest.join("/")));
  else if (next === "alarms") views.alarms.open();
  else if (next === "models") views.models.open();
  else if (next === "audit") views.audit.open();
  else views.overview.dirty = true;
}
window.addEventListener("hashchange", route);

// ------------------------------------------------------------------ status + auth

const status = $("status");
let unreachableSince = 0;
function setStatus(state, text) {
  if (status.dataset.state === state && status.textContent === text) return;
  status.dataset.state = state;
  status.textContent = text;
  document.body.classList.toggle("stale", state === "unreachable");
}

onReachability((ok) => {
  if (ok) {
    if (unreachableSince) { unreachableSince = 0; live.serverBack(); }
  } else {
    if (!unreachableSince) unreachableSince = Date.now();
    setStatus("unreachable", "Server unreachable since " + fmtClock(unreachableSince) + " \u2014 retrying; values shown are the last known.");
  }
});
live.on("status", (state) => {
  if (state === "ok") {
    const n = live.sessions.size;
    setStatus("ok", "Server reachable \u00b7 " + n + (n === 1 ? " session" : " sessions"));
  }
});

const authForm = $("auth");
onAuthNeeded((hadToken) => {
  if (!authForm.hidden) return;
  live.pause();
  setStatus("auth", "This server needs an access token.");
  $("auth-msg").textContent = hadToken ? "The server refused that token; enter the current one." : "";
  authForm.hidden = false;
  $("token").focus();
});
authForm.addEventListener("submit", (ev) => {
  ev.preventDefault();
  const value = $("token").value.trim();
  if (!/^[\x21-\x7e]+$/.test(value)) { $("auth-msg").textContent = "A token is printable ASCII without spaces."; return; }
  setToken(value);
  $("token").value = "";
  authForm.hidden = true;
  setStatus("loading", "Connecting with the token\u2026");
  live.restart();
  route();
  applyScopes();
});

// ------------------------------------------------------------------ scopes

// Controls marked `data-needs="SCOPE"` are hidden (app.css) while the body has the
// class `lacks-SCOPE`: the token cannot use them (the server would answer 403).
const SCOPES = ["ingest", "read", "operate", "admin"];
async function applyScopes() {
  let me;
  try { me = await whoami(); } catch (_) { return; /* a 401 asks for the token, which calls this again */ }
  const has = new Set(me ? me.scopes : SCOPES);
  for (const s of SCOPES) document.body.classList.toggle("lacks-" + s, !has.has(s));
  $("whoami").textContent = me && me.name !== "anonymous" ? "Token “" + me.name + "”: " + me.scopes.join(", ") : "";
}

// ------------------------------------------------------------------ render loop

/** Durations of frames that rendered something, ms (bounded). */
const frameMs = [];
/** Time between consecutive animation frames, ms: above ~17 ms the page drops frames. */
const intervalMs = [];
let lastFrameAt = 0;
function frame(now) {
  if (lastFrameAt) { intervalMs.push(now - lastFrameAt); if (intervalMs.length > 5000) intervalMs.splice(0, 2500); }
  lastFrameAt = now;
  const started = performance.now();
  try { views[current].render(); } catch (e) { console.error(e); }
  const took = performance.now() - started;
  if (took > 0.05) { frameMs.push(took); if (frameMs.length > 5000) frameMs.splice(0, 2500); }
  requestAnimationFrame(frame);
}

function summary(list) {
  const a = [...list].sort((x, y) => x - y);
  if (!a.length) return { n: 0 };
  const q = (p) => a[Math.min(a.length - 1, Math.floor(p * a.length))];
  return { n: a.length, mean: a.reduce((x, y) => x + y, 0) / a.length, p50: q(0.5), p95: q(0.95), max: a[a.length - 1] };
}

/** Render-frame and message-handling times, for the browser test and the curious. */
window.navguardPerf = (reset) => {
  const out = { frame: summary(frameMs), interval: summary(intervalMs), message: summary(live.handleMs) };
  if (reset) { frameMs.length = 0; intervalMs.length = 0; live.handleMs.length = 0; }
  return out;
};

// Ages and "reconnecting in" countdowns move with the clock.
setInterval(() => { views.overview.tick(); views.session.headDirty = true; }, 500);

// The store, for the browser console (and the browser test's diagnostics).
window.navguardLive = live;

route();
live.start();
applyScopes();
requestAnimationFrame(frame);
