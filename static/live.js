// live.js — the page's model of the server: the session list (polled over
// REST, so new sessions appear without a reload), one events socket per
// session (stats, state, alarm and availability messages), and a bounded
// history of every test's statistic, and of every protection level against
// its alert limit, for the charts (and for gnss monitors their horizontal and
// vertical levels, errors and latest satellites). Views read from here and subscribe to
// changes; nothing here touches the DOM.

import { get, socketUrl, AuthError } from "./api.js";
import { isNum } from "./dom.js";

const POLL_MS = 2000;
const BACKOFF_MIN_MS = 500;
const BACKOFF_MAX_MS = 30000;
/** A socket open this long counts as healthy and resets the backoff. */
const STABLE_OPEN_MS = 10000;
/** Points kept per test: 20 stats/s for 5 minutes. Trimmed in chunks (amortised O(1)). */
const HISTORY_CAP = 6000;
/** Track points kept per federated monitor (about 17 minutes at 20 stats/s). Trimmed in chunks. */
const TRACK_CAP = 20000;
/** GNSS epochs kept per gnss monitor (over an hour at 1 Hz). Trimmed in chunks. */
const GNSS_CAP = 6000;
/** WGS84 semi-major axis (m) and first eccentricity squared, for the local ENU frame. */
const WGS84_A = 6378137.0;
const WGS84_E2 = 6.69437999014e-3;
/** Recent alarms kept in memory for the overview and session views. */
const RECENT_ALARMS = 200;
/** The series key of a monitor's protection level ("#" cannot start a test name). */
export const INTEGRITY = "#integrity";
/**
 * Availability drawn with the test bands: converging amber, unavailable red.
 * Availability is not a fault; the chart's caption says which is which.
 */
export const AVAILABILITY_BAND = { available: "healthy", converging: "suspect", unavailable: "isolated" };

/**
 * One test's history: parallel arrays (cheaper than objects at 20 Hz × many
 * tests) plus the state transitions the `state` messages report exactly,
 * which the `stats` samples (≤ 20/s) could miss between two snapshots.
 */
export class Series {
  constructor() {
    this.t = []; this.v = []; this.thr = []; this.state = [];
    this.transitions = []; // {t, to}
    this.lastEpochs = -1;
    this.firstState = null;
  }
  push(t, v, thr, state) {
    if (this.t.length && t < this.t[this.t.length - 1]) this.clear(); // stream restarted (t went back)
    this.t.push(t); this.v.push(v); this.thr.push(thr); this.state.push(state);
    if (this.firstState === null) this.firstState = state;
    if (this.t.length > 2 * HISTORY_CAP) this.trim();
  }
  /**
   * Puts `points` ({t, v, thr, state}, oldest first) before what is held: the past a
   * history request returned, older than the live samples (later ones are dropped).
   */
  prepend(points) {
    const first = this.t.length ? this.t[0] : Infinity;
    const older = points.filter((p) => p.t < first);
    if (!older.length) return;
    this.t = older.map((p) => p.t).concat(this.t);
    this.v = older.map((p) => p.v).concat(this.v);
    this.thr = older.map((p) => p.thr).concat(this.thr);
    this.state = older.map((p) => p.state).concat(this.state);
    this.firstState = older[0].state;
    if (this.t.length > 2 * HISTORY_CAP) this.trim();
  }
  transition(t, to) {
    this.transitions.push({ t, to });
    if (this.transitions.length > HISTORY_CAP) this.transitions.splice(0, this.transitions.length - HISTORY_CAP);
  }
  trim() {
    const drop = this.t.length - HISTORY_CAP;
    for (const a of [this.t, this.v, this.thr, this.state]) a.splice(0, drop);
    const t0 = this.t[0];
    let i = 0;
    while (i < this.transitions.length && this.transitions[i].t < t0) i++;
    // Keep the last transition before the window: it gives the state at its start.
    if (i > 1) this.transitions.splice(0, i - 1);
  }
  clear() {
    this.t = []; this.v = []; this.thr = []; this.state = [];
    this.transitions = []; this.firstState = null; this.lastEpochs = -1;
  }
  get length() { return this.t.length; }

  /**
   * Intervals [t0, t1) spent suspect or isolated, from the exact transitions
   * where we have them and the sampled states otherwise.
   */
  bands() {
    // Cached: charts ask on every redraw, the answer changes only with new data.
    const key = this.t.length + ":" + this.transitions.length + ":" + this.t[this.t.length - 1];
    if (this.bandsKey !== key) { this.bandsKey = key; this.bandsCache = this.computeBands(); }
    return this.bandsCache;
  }

  computeBands() {
    const marks = [];
    const n = this.t.length;
    if (!n) return [];
    // Sampled states give a transition wherever two samples differ.
    let prev = this.state[0];
    marks.push({ t: this.t[0], to: prev });
    for (let i = 1; i < n; i++) {
      if (this.state[i] !== prev) { marks.push({ t: this.t[i], to: this.state[i] }); prev = this.state[i]; }
    }
    for (const m of this.transitions) marks.push(m);
    marks.sort((a, b) => a.t - b.t);
    const out = [];
    let open = null;
    for (const m of marks) {
      if (open && open.state !== m.to) { open.t1 = m.t; out.push(open); open = null; }
      if (!open && (m.to === "suspect" || m.to === "isolated")) open = { t0: m.t, t1: Infinity, state: m.to };
    }
    if (open) { open.t1 = this.t[n - 1]; out.push(open); }
    return out;
  }
}

/**
 * One federated monitor's corrected and raw INS tracks, as the `stats`
 * messages sample them (≤ 20/s, so a 10 Hz INS is thinned, never invented).
 * Stored as east/north metres from the first point received: converting once
 * on arrival keeps redraws to plain arithmetic. The frame is the tangent
 * plane at that origin with the ellipsoid's radii there — metre-accurate over
 * the tens of kilometres a session covers, which is all a track plot needs.
 */
export class Track {
  constructor() { this.clear(); }
  clear() {
    this.t = []; this.sE = []; this.sN = []; this.iE = []; this.iN = [];
    this.origin = null; // {lat, lon (deg), rn, re (m per rad)}
    // With `input: imu` the track carries the alignment state, and its INS position is
    // the solution (the mechanization after the closed-loop feedback): one track, not two.
    this.alignment = null; // the latest track's, null for a monitor fed a client's INS
    this.mechanized = false;
    this.distinct = false; // some INS point differs from its solution
    this.version = (this.version || 0) + 1; // lets a chart tell new data from a redraw
  }
  get length() { return this.t.length; }
  /** Puts history tracks (oldest first) before what is held, keeping the origin of the oldest. */
  prepend(list) {
    const first = this.t.length ? this.t[0] : Infinity;
    const older = list.filter((tr) => tr.t < first);
    if (!older.length) return;
    const newer = this.t.map((t, i) => i);
    const keep = { t: this.t.slice(), sE: this.sE, sN: this.sN, iE: this.iE, iN: this.iN, origin: this.origin,
      alignment: this.alignment, mechanized: this.mechanized, distinct: this.distinct };
    this.clear();
    for (const tr of older) this.push(tr);
    // The live state is newer than any history sample's.
    if (keep.alignment) this.alignment = keep.alignment;
    this.mechanized = this.mechanized || keep.mechanized;
    this.distinct = this.distinct || keep.distinct;
    if (keep.origin && this.origin) {
      // Re-express the held points in the new (older) origin's frame.
      const o = this.origin, k = Math.PI / 180;
      const dE = (keep.origin.lon - o.lon) * k * o.re, dN = (keep.origin.lat - o.lat) * k * o.rn;
      for (const i of newer) {
        this.t.push(keep.t[i]);
        this.sE.push(keep.sE[i] + dE); this.sN.push(keep.sN[i] + dN);
        this.iE.push(keep.iE[i] + dE); this.iN.push(keep.iN[i] + dN);
      }
    }
    this.version++;
  }
  /**
   * Adds the `track` of one stats message; repeats (no new INS epoch) are skipped,
   * but a new alignment state is kept (it moves while the position stays).
   */
  push(tr) {
    const n = this.t.length;
    if (n && tr.t < this.t[n - 1]) this.clear(); // stream restarted (t went back)
    if (typeof tr.alignment === "string") {
      if (this.alignment !== tr.alignment) { this.alignment = tr.alignment; this.version++; }
      this.mechanized = true;
    }
    if (this.t.length && tr.t === this.t[this.t.length - 1]) return false;
    if (!this.origin) {
      const lat = tr.solution.lat * Math.PI / 180, sin = Math.sin(lat);
      const w = Math.sqrt(1 - WGS84_E2 * sin * sin);
      const h = tr.solution.h;
      // Meridian and prime-vertical radii of curvature at the origin.
      const rn = WGS84_A * (1 - WGS84_E2) / (w * w * w) + h;
      const re = (WGS84_A / w + h) * Math.cos(lat);
      this.origin = { lat: tr.solution.lat, lon: tr.solution.lon, rn, re };
    }
    const o = this.origin, k = Math.PI / 180;
    this.t.push(tr.t);
    this.sE.push((tr.solution.lon - o.lon) * k * o.re); this.sN.push((tr.solution.lat - o.lat) * k * o.rn);
    this.iE.push((tr.ins.lon - o.lon) * k * o.re); this.iN.push((tr.ins.lat - o.lat) * k * o.rn);
    if (tr.ins.lat !== tr.solution.lat || tr.ins.lon !== tr.solution.lon) this.distinct = true;
    if (this.t.length > TRACK_CAP + TRACK_CAP / 4) {
      // Drop the oldest in one splice per TRACK_CAP / 4 points (amortised O(1)); the origin stays.
      const drop = this.t.length - TRACK_CAP;
      for (const a of [this.t, this.sE, this.sN, this.iE, this.iN]) a.splice(0, drop);
    }
    this.version++;
    return true;
  }
}

/**
 * One gnss monitor's protection levels over time and its latest epoch, from
 * the `gnss` snapshot of each stats message. The snapshot repeats until the
 * next epoch with pseudoranges, so a repeated `t` is skipped. Parallel arrays
 * of t, hpl, vpl, hal, val, hpe, vpe (null where the epoch had none: no
 * solution, no VAL configured, no truth position).
 */
export class GnssHistory {
  constructor() { this.clear(); }
  clear() {
    this.t = []; this.hpl = []; this.vpl = []; this.hal = []; this.val = []; this.hpe = []; this.vpe = [];
    this.latest = null; // the last snapshot as received
    this.version = (this.version || 0) + 1; // lets a chart tell new data from a redraw
  }
  get length() { return this.t.length; }
  /** Adds one snapshot; false when it repeats the last epoch. */
  push(g) {
    const n = this.t.length;
    if (n && g.t === this.t[n - 1]) return false;
    if (n && g.t < this.t[n - 1]) this.clear(); // stream restarted (t went back)
    this.append(g);
    this.latest = g;
    this.version++;
    if (this.t.length > GNSS_CAP + GNSS_CAP / 4) {
      const drop = this.t.length - GNSS_CAP;
      for (const a of this.arrays()) a.splice(0, drop);
    }
    return true;
  }
  /** Puts history snapshots (oldest first) before what is held; the latest stays. */
  prepend(list) {
    const first = this.t.length ? this.t[0] : Infinity;
    const older = list.filter((g) => isNum(g.t) && g.t < first);
    if (!older.length) return;
    const keep = this.arrays().map((a) => a.slice());
    const latest = this.latest || older[older.length - 1];
    this.clear();
    for (const g of older) this.append(g);
    this.arrays().forEach((a, k) => { for (const v of keep[k]) a.push(v); });
    if (this.t.length > GNSS_CAP) for (const a of this.arrays()) a.splice(0, this.t.length - GNSS_CAP);
    this.latest = latest;
    this.version++;
  }
  /** Takes a full snapshot (with satellites) as the latest unless a newer one is held. */
  adoptLatest(g) {
    if (this.latest && Array.isArray(this.latest.satellites) && this.latest.t >= g.t) return;
    const n = this.t.length;
    if (!n || g.t > this.t[n - 1]) { this.push(g); return; }
    this.latest = g;
    this.version++;
  }
  append(g) {
    const num = (x) => (isNum(x) ? x : null);
    this.t.push(g.t); this.hpl.push(num(g.hpl)); this.vpl.push(num(g.vpl)); this.hal.push(num(g.hal));
    this.val.push(num(g.val)); this.hpe.push(num(g.hpe)); this.vpe.push(num(g.vpe));
  }
  arrays() { return [this.t, this.hpl, this.vpl, this.hal, this.val, this.hpe, this.vpe]; }
}

/** Everything the page knows about one session. */
class SessionLive {
  constructor(id) {
    this.id = id;
    this.info = null;      // GET /api/v1/sessions entry (spec + test states)
    this.stats = null;     // last `stats` message
    this.statsAt = 0;      // our clock when it arrived
    this.series = new Map(); // "monitor/test" → Series
    this.tracks = new Map(); // federated monitor name → Track
    this.gnss = new Map();   // gnss monitor name → GnssHistory
    this.ws = null; this.openedAt = 0; this.delay = BACKOFF_MIN_MS;
    this.retryTimer = null; this.retryAt = 0; this.removed = false;
    this.maxAlarmId = 0;
  }
  seriesFor(monitor, test) {
    const key = monitor + "/" + test;
    let s = this.series.get(key);
    if (!s) { s = new Series(); this.series.set(key, s); }
    return s;
  }
  trackFor(monitor) {
    let tr = this.tracks.get(monitor);
    if (!tr) { tr = new Track(); this.tracks.set(monitor, tr); }
    return tr;
  }
  gnssFor(monitor) {
    let g = this.gnss.get(monitor);
    if (!g) { g = new GnssHistory(); this.gnss.set(monitor, g); }
    return g;
  }
  /** "live", "connecting…", "reconnecting in N s" or "off". */
  liveText() {
    if (this.ws && this.ws.readyState === WebSocket.OPEN) return "live";
    if (this.ws) return "connecting\u2026";
    if (this.retryTimer) return "reconnecting in " + Math.max(1, Math.ceil((this.retryAt - Date.now()) / 1000)) + " s";
    return "off";
  }
  /** Monitors as [{name, type, spec, tests: {name: {state, dof, threshold, ...}}}]: REST spec + live stats. */
  monitors() {
    const out = [];
    const byName = new Map();
    for (const m of (this.info && this.info.monitors) || []) {
      const entry = { name: m.name, type: m.type, spec: m, tests: Object.assign({}, m.tests || {}) };
      byName.set(m.name, entry); out.push(entry);
    }
    for (const [name, m] of Object.entries((this.stats && this.stats.monitors) || {})) {
      let entry = byName.get(name);
      if (!entry) { entry = { name, type: m.type, spec: null, tests: {} }; byName.set(name, entry); out.push(entry); }
      entry.live = m;
      for (const [t, ts] of Object.entries(m.tests || {})) entry.tests[t] = ts;
    }
    return out;
  }
}

/** The store. `on(kind, fn)` with kind in sessions | stats | state | alarm | status. */
export class Live {
  constructor() {
    this.sessions = new Map();
    this.recentAlarms = [];
    this.listeners = new Map();
    this.pollTimer = null;
    this.loaded = false;
    this.paused = false; // true while the page waits for a token
    /** Sessions whose history was asked for before the list named them (a URL opened directly). */
    this.historyWanted = new Set();
    /** Time spent handling socket messages, ms (the browser test reads it). */
    this.handleMs = [];
  }

  on(kind, fn) {
    if (!this.listeners.has(kind)) this.listeners.set(kind, new Set());
    this.listeners.get(kind).add(fn);
    return () => this.listeners.get(kind).delete(fn);
  }
  emit(kind, ...args) {
    for (const fn of this.listeners.get(kind) || []) {
      try { fn(...args); } catch (e) { console.error(e); }
    }
  }

  start() { this.paused = false; this.poll(); this.loadRecentAlarms(); }

  /** Stops sockets and polling until `restart()` (e.g. while asking for a token). */
  pause() {
    this.paused = true;
    clearTimeout(this.pollTimer);
    for (const s of this.sessions.values()) this.closeSocket(s);
  }

  restart() {
    this.paused = false;
    for (const s of this.sessions.values()) { s.delay = BACKOFF_MIN_MS; this.connect(s); }
    this.start();
  }

  /** The server answered again after an outage: retry sockets now, not at the end of their backoff. */
  serverBack() {
    for (const s of this.sessions.values()) if (s.retryTimer) { s.delay = BACKOFF_MIN_MS; this.connect(s); }
  }

  async poll() {
    clearTimeout(this.pollTimer);
    if (this.paused) return;
    try {
      const data = await get("api/v1/sessions");
      this.sync(Array.isArray(data && data.sessions) ? data.sessions : []);
      this.emit("status", "ok");
    } catch (e) {
      if (!(e instanceof AuthError)) this.emit("status", "error", e);
    } finally {
      if (!this.paused) this.pollTimer = setTimeout(() => this.poll(), POLL_MS);
    }
  }

  sync(list) {
    const seen = new Set();
    for (const info of list) {
      if (!info || typeof info.id !== "string") continue;
      seen.add(info.id);
      let s = this.sessions.get(info.id);
      if (!s) { s = new SessionLive(info.id); this.sessions.set(info.id, s); }
      s.info = info;
      if (!s.ws && !s.retryTimer) this.connect(s);
      if (this.historyWanted.delete(info.id)) this.loadHistory(info.id);
    }
    for (const [id, s] of this.sessions) {
      if (!seen.has(id)) { s.removed = true; this.closeSocket(s); this.sessions.delete(id); }
    }
    this.loaded = true;
    this.emit("sessions");
  }

  /**
   * Draws the past: the session's 1 Hz statistics history (GET …/history) goes before
   * the live samples, once per session (a view opened mid-run starts with it). Asked for
   * before the session list has named the session (the page opened on its URL), it is
   * loaded as soon as the list does.
   */
  async loadHistory(id) {
    const s = this.sessions.get(id);
    if (!s) { this.historyWanted.add(id); return; }
    if (s.historyLoaded) return;
    s.historyLoaded = true;
    let h;
    try { h = await get("api/v1/sessions/" + encodeURIComponent(id) + "/history"); } catch (_) {
      // Asked again after the next poll of the list (a token prompt or an outage passes).
      s.historyLoaded = false;
      this.historyWanted.add(id);
      return;
    }
    const tests = new Map(), integrity = new Map(), tracks = new Map(), gnss = new Map();
    for (const sample of (h && h.samples) || []) {
      for (const [m, mv] of Object.entries(sample.monitors || {})) {
        for (const [t, tv] of Object.entries(mv.tests || {})) {
          const key = m + "/" + t;
          if (!tests.has(key)) tests.set(key, []);
          tests.get(key).push({ t: sample.t, v: tv.last, thr: tv.threshold, state: tv.state });
        }
        if (mv.integrity) {
          if (!integrity.has(m)) integrity.set(m, []);
          const i = mv.integrity;
          // A null level (not yet known: an imu monitor aligning) has no point to draw.
          if (isNum(i.protection_level)) integrity.get(m).push({ t: sample.t, v: i.protection_level, thr: i.alert_limit, state: AVAILABILITY_BAND[i.state] || "unknown" });
        }
        if (mv.track) {
          if (!tracks.has(m)) tracks.set(m, []);
          tracks.get(m).push(mv.track);
        }
        if (mv.gnss && isNum(mv.gnss.t)) {
          if (!gnss.has(m)) gnss.set(m, []);
          gnss.get(m).push(mv.gnss);
        }
      }
    }
    for (const [key, points] of tests) {
      const [m, ...rest] = key.split("/");
      s.seriesFor(m, rest.join("/")).prepend(points);
    }
    for (const [m, points] of integrity) s.seriesFor(m, INTEGRITY).prepend(points);
    for (const [m, list] of tracks) s.trackFor(m).prepend(list);
    for (const [m, list] of gnss) s.gnssFor(m).prepend(list);
    if (gnss.size) await this.loadGnssLatest(s, [...gnss.keys()]);
    this.emit("stats", s);
  }

  /**
   * The history carries a gnss monitor's levels, not its satellites: the latest
   * epoch's (sky plot, residuals) come from the session's current stats.
   */
  async loadGnssLatest(s, monitors) {
    let st;
    try { st = await get("api/v1/sessions/" + encodeURIComponent(s.id) + "/stats"); } catch (_) { return; }
    for (const m of monitors) {
      const snap = st && st.monitors && st.monitors[m] && st.monitors[m].gnss;
      if (snap && isNum(snap.t)) s.gnssFor(m).adoptLatest(snap);
    }
  }

  /** Refreshes one session's REST view now (after a threshold change, say). */
  async refresh(id) {
    try {
      const info = await get("api/v1/sessions/" + encodeURIComponent(id));
      const s = this.sessions.get(id);
      if (s) { s.info = info; this.emit("sessions"); }
    } catch (_) { /* the next poll will tell */ }
  }

  // ------------------------------------------------------------ sockets

  connect(s) {
    clearTimeout(s.retryTimer);
    s.retryTimer = null;
    if (s.removed || this.paused) return;
    if (s.ws) return;
    let ws;
    try {
      ws = new WebSocket(socketUrl("api/v1/sessions/" + encodeURIComponent(s.id) + "/events"));
    } catch (_) { this.scheduleRetry(s); return; }
    s.ws = ws;
    s.openedAt = 0;
    ws.onopen = () => {
      if (s.ws !== ws) return;
      s.openedAt = Date.now();
      // Alarms raised while we were not subscribed are only in the log.
      this.catchUpAlarms(s);
      this.emit("sessions");
    };
    ws.onmessage = (ev) => {
      if (s.ws !== ws) return;
      const started = performance.now();
      let msg;
      try { msg = JSON.parse(ev.data); } catch (_) { return; }
      if (msg && msg.type === "stats") this.onStats(s, msg);
      else if (msg && msg.type === "state") this.onState(s, msg);
      else if (msg && msg.type === "alarm") this.onAlarm(msg, true);
      else if (msg && msg.type === "availability") this.onAvailability(s, msg);
      this.handleMs.push(performance.now() - started);
      if (this.handleMs.length > 5000) this.handleMs.splice(0, 2500);
    };
    ws.onclose = () => {
      if (s.ws !== ws) return;
      s.ws = null;
      if (s.removed || this.paused) return;
      if (s.openedAt && Date.now() - s.openedAt >= STABLE_OPEN_MS) s.delay = BACKOFF_MIN_MS;
      this.scheduleRetry(s);
      this.emit("sessions");
    };
  }

  /** Exponential backoff with ±10 % jitter, so many tabs do not reconnect in step. */
  scheduleRetry(s) {
    clearTimeout(s.retryTimer);
    const delay = Math.round(s.delay * (0.9 + Math.random() * 0.2));
    s.retryAt = Date.now() + delay;
    s.retryTimer = setTimeout(() => this.connect(s), delay);
    s.delay = Math.min(s.delay * 2, BACKOFF_MAX_MS);
  }

  closeSocket(s) {
    clearTimeout(s.retryTimer);
    s.retryTimer = null;
    if (s.ws) {
      const ws = s.ws;
      s.ws = null;
      try { ws.close(1000, "closing"); } catch (_) { /* already closed */ }
    }
  }

  // ------------------------------------------------------------ messages

  onStats(s, st) {
    s.stats = st;
    s.statsAt = Date.now();
    const t = st.last_t;
    if (isNum(t)) {
      for (const [mname, m] of Object.entries(st.monitors || {})) {
        for (const [tname, ts] of Object.entries(m.tests || {})) {
          // Only a test that ran since the last snapshot has a new statistic
          // (an aid at 1 Hz keeps its old `last` through the INS's 10 Hz epochs).
          const series = s.seriesFor(mname, tname);
          if (ts.epochs === series.lastEpochs || !isNum(ts.last)) continue;
          if (ts.epochs < series.lastEpochs) series.clear(); // the stream restarted
          series.lastEpochs = ts.epochs;
          series.push(t, ts.last, ts.threshold, ts.state);
        }
      }
    }
    // Federated monitors carry their latest corrected and INS positions, and
    // monitors with a protection level their integrity.
    for (const [mname, m] of Object.entries(st.monitors || {})) {
      if (m.track && isNum(m.track.t)) s.trackFor(mname).push(m.track);
      if (m.gnss && isNum(m.gnss.t)) s.gnssFor(mname).push(m.gnss);
      const i = m.integrity;
      if (i && isNum(t) && isNum(i.protection_level)) {
        const series = s.seriesFor(mname, INTEGRITY);
        if (m.epochs < series.lastEpochs) series.clear();
        if (m.epochs !== series.lastEpochs) {
          series.lastEpochs = m.epochs;
          series.push(t, i.protection_level, i.alert_limit, AVAILABILITY_BAND[i.state] || "unknown");
        }
      }
    }
    this.emit("stats", s);
  }

  onAvailability(s, msg) {
    if (typeof msg.monitor !== "string") return;
    s.seriesFor(msg.monitor, INTEGRITY).transition(msg.t, AVAILABILITY_BAND[msg.to] || "unknown");
    const m = s.stats && s.stats.monitors && s.stats.monitors[msg.monitor];
    if (m && m.integrity) m.integrity.state = msg.to;
    this.emit("availability", s, msg);
  }

  onState(s, msg) {
    if (typeof msg.monitor !== "string" || typeof msg.test !== "string") return;
    s.seriesFor(msg.monitor, msg.test).transition(msg.t, msg.to);
    const m = s.stats && s.stats.monitors && s.stats.monitors[msg.monitor];
    if (m && m.tests && m.tests[msg.test]) m.tests[msg.test].state = msg.to;
    if (msg.to === "healthy") {
      // Mirrors the server: a return to healthy clears that test's open alarms.
      for (const a of this.recentAlarms) {
        if (a.session === s.id && a.monitor === msg.monitor && a.test === msg.test && a.cleared_t == null) a.cleared_t = msg.t;
      }
    } else if (msg.severity === "warning") {
      // A warning is announced only as this state change; its log entry is read back.
      this.catchUpAlarms(s);
    }
    this.emit("state", s, msg);
  }

  /** Adds an alarm (live or from the log) to the recent list, newest first, once. */
  onAlarm(a, live) {
    if (!a || typeof a !== "object") return;
    if (a.id > 0 && this.recentAlarms.some((b) => b.id === a.id)) return;
    const s = this.sessions.get(a.session);
    if (s && a.id > s.maxAlarmId) s.maxAlarmId = a.id;
    let i = 0;
    // Ids grow with insertion; an unstored alarm (id -1) goes by its clock.
    const newer = (x, y) => (x.id > 0 && y.id > 0 ? x.id > y.id : (x.raised_at_ms || 0) > (y.raised_at_ms || 0));
    while (i < this.recentAlarms.length && !newer(a, this.recentAlarms[i])) i++;
    if (i >= RECENT_ALARMS) return;
    this.recentAlarms.splice(i, 0, Object.assign({ live }, a));
    if (this.recentAlarms.length > RECENT_ALARMS) this.recentAlarms.pop();
    this.emit("alarm", a, live);
  }

  async loadRecentAlarms() {
    try {
      const page = await get("api/v1/alarms?limit=50");
      for (const a of (page && page.alarms) || []) this.onAlarm(a, false);
    } catch (_) { /* shown by the status line */ }
  }

  async catchUpAlarms(s) {
    try {
      const q = "api/v1/alarms?limit=100&session=" + encodeURIComponent(s.id) + (s.maxAlarmId > 0 ? "&after=" + s.maxAlarmId : "");
      const page = await get(q);
      for (const a of ((page && page.alarms) || []).reverse()) this.onAlarm(a, false);
    } catch (_) { /* a 401 asks for the token; anything else shows in the status line */ }
  }
}
