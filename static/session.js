// session.js — one session in detail: for each monitor a strip chart per
// test (statistic against threshold, suspect/isolated bands), HPL against HAL
// for federated monitors with their corrected track against the raw INS
// track (or, on raw IMU, the mechanized solution with its alignment state), a gnss monitor's sky plot, levels, residuals and Stanford diagram
// (gnss.js), the threshold controls, and the session's alarms.
// All charts of the session share one time range, so zooming one zooms all.

import { el, setText, badge, setBadge, fmtNum, fmtRatio, fmtT, fmtClock, policyLevelText, isNum, severityTag, consistencyText } from "./dom.js";
import { StripChart, TrackChart } from "./chart.js";
import { ThresholdControls } from "./controls.js";
import { INTEGRITY } from "./live.js";
import { download } from "./api.js";
import { GnssPanel } from "./gnss.js";

const SESSION_ALARMS = 50;

/** What each alignment state of a federated monitor on raw IMU waits for. */
const ALIGNMENT_TEXT = {
  levelling: "levelling \u2014 waiting for a still vehicle and a GNSS fix",
  heading: "heading \u2014 levelled, waiting for speed",
  aligned: "aligned",
  aligning: "aligning \u2014 levelling, or levelled and waiting for speed",
};

/** Whether a federated monitor mechanizes raw IMU (`input: imu`): from its spec, or its stats. */
function onImu(m) {
  return !!((m.spec && m.spec.config && m.spec.config.input === "imu") ||
    (m.live && (m.live.alignment || (m.live.track && m.live.track.alignment))));
}

/**
 * The alignment state of a federated monitor on raw IMU, or null for one fed a
 * client's INS: the stats' `alignment` (after every IMU epoch), else its track's.
 * Before the first IMU epoch there is neither: with a configured heading the state
 * can only be levelling; without one "aligning".
 */
export function alignmentOf(m) {
  if (m.type !== "federated" || !onImu(m)) return null;
  if (m.live && ALIGNMENT_TEXT[m.live.alignment]) return m.live.alignment;
  const tr = m.live && m.live.track;
  if (tr && ALIGNMENT_TEXT[tr.alignment]) return tr.alignment;
  const align = m.spec && m.spec.config && m.spec.config.strapdown && m.spec.config.strapdown.align;
  return align && isNum(align.heading_deg) ? "levelling" : "aligning";
}

export class SessionView {
  constructor(live, root) {
    this.live = live;
    this.root = root;
    this.id = null;
    this.shape = "";
    this.charts = [];       // {chart, monitor, test, caption}
    this.tracks = [];       // {chart, track, value}: one per federated monitor
    this.gnss = [];         // GnssPanel: one per gnss monitor
    this.range = null;      // shared zoom [t0, t1]
    this.paused = false;
    this.log = false;
    this.alarmsDirty = true;
    this.headDirty = true;
    this.title = root.querySelector("#session-title");
    this.body = root.querySelector("#session-monitors");
    this.alarmBody = root.querySelector("#session-alarms");
    this.facts = root.querySelector("#session-facts");
    this.rangeText = root.querySelector("#range-text");
    this.pauseBtn = root.querySelector("#pause");
    this.logBox = root.querySelector("#log-scale");
    this.pauseBtn.addEventListener("click", () => this.setPaused(!this.paused));
    this.logBox.addEventListener("change", () => {
      this.log = this.logBox.checked;
      for (const c of this.charts) c.chart.setLog(this.log);
    });
    root.querySelector("#reset-zoom").addEventListener("click", () => this.setRange(null));
    this.downloadBtn = root.querySelector("#download-recording");
    this.downloadMsg = root.querySelector("#download-msg");
    this.downloadBtn.addEventListener("click", async () => {
      if (!this.id) return;
      this.downloadMsg.textContent = "Downloading\u2026";
      try {
        await download("api/v1/sessions/" + encodeURIComponent(this.id) + "/recording", "recording-" + this.id + ".jsonl");
        this.downloadMsg.textContent = "";
      } catch (e) {
        this.downloadMsg.textContent = e.message;
      }
    });
    live.on("stats", (s) => {
      if (s.id !== this.id) return;
      this.headDirty = true;
      // Paused or zoomed: the visible window is fixed, new points land outside it.
      if (!this.paused && !this.range) for (const c of this.charts) c.chart.invalidate();
    });
    live.on("state", (s) => {
      if (s.id !== this.id) return;
      // A return to healthy also clears alarms in the list below.
      this.headDirty = true;
      this.alarmsDirty = true;
      for (const c of this.charts) c.chart.invalidate();
    });
    live.on("alarm", (a) => { if (a.session === this.id) this.alarmsDirty = true; });
    live.on("availability", (s) => {
      if (s.id !== this.id) return;
      this.headDirty = true;
      for (const c of this.charts) c.chart.invalidate();
      for (const p of this.gnss) p.invalidate();
    });
    live.on("sessions", () => { this.headDirty = true; });
  }

  /** Shows session `id` (called by the router). */
  open(id) {
    if (this.id !== id) {
      this.id = id;
      this.shape = "";
      this.range = null;
      this.setPaused(false);
      this.body.replaceChildren();
      this.charts = [];
      this.tracks = [];
      this.gnss = [];
    }
    this.headDirty = true;
    this.alarmsDirty = true;
    this.live.loadHistory(id);
  }

  setPaused(on) {
    this.paused = on;
    setText(this.pauseBtn, on ? "Resume" : "Pause");
    this.pauseBtn.setAttribute("aria-pressed", on ? "true" : "false");
    if (on && !this.range) {
      // Freeze the window where it is now.
      const s = this.live.sessions.get(this.id);
      const first = s && [...s.series.values()].find((x) => x.length);
      if (first) this.range = [first.t[0], first.t[first.length - 1]];
    } else if (!on) {
      this.range = null;
    }
    this.applyRange();
  }

  setRange(range) {
    this.range = range;
    if (!range && this.paused) { this.paused = false; setText(this.pauseBtn, "Pause"); this.pauseBtn.setAttribute("aria-pressed", "false"); }
    this.applyRange();
  }

  applyRange() {
    for (const c of this.charts) c.chart.setRange(this.range);
    for (const p of this.gnss) p.setRange(this.range);
    setText(this.rangeText, this.range ? "showing t " + fmtT(this.range[0]) + " \u2013 " + fmtT(this.range[1]) + " s" : "live");
  }

  render() {
    const s = this.live.sessions.get(this.id);
    if (!s) {
      setText(this.title, "Session " + this.id + (this.live.loaded ? " (not found)" : ""));
      return;
    }
    const monitors = s.monitors();
    const shape = JSON.stringify(monitors.map((m) => [m.name, Object.keys(m.tests), !!(m.live && m.live.integrity), onImu(m)]));
    if (shape !== this.shape) { this.shape = shape; this.build(s, monitors); }
    if (this.headDirty) { this.headDirty = false; this.fillHead(s, monitors); }
    for (const c of this.charts) c.chart.draw();
    // Tracks ignore pause and zoom: they are a map of where the vehicle went, not a time window.
    for (const tc of this.tracks) {
      if (!tc.chart.draw()) continue;
      const tr = tc.track, n = tr.length;
      // On raw IMU the INS is the solution: there is no INS − corrected distance to show.
      const gap = tr.mechanized ? "" : "INS \u2212 corrected " + fmtNum(Math.hypot(tr.iE[n - 1] - tr.sE[n - 1], tr.iN[n - 1] - tr.sN[n - 1])) + " m \u00b7 ";
      setText(tc.value, n ? gap + n + " points" : "");
    }
    for (const p of this.gnss) p.draw();
    if (this.alarmsDirty) { this.alarmsDirty = false; this.fillAlarms(); }
  }

  build(s, monitors) {
    setText(this.title, "Session " + s.id);
    this.charts = [];
    this.tracks = [];
    this.gnss = [];
    const cards = monitors.map((m) => {
      const tests = Object.keys(m.tests).sort();
      // The protection level first: for a federated monitor it is the integrity headline.
      // A gnss monitor draws its HPL with its VPL in its own chart (below) instead.
      if (m.live && m.live.integrity && m.type !== "gnss") tests.unshift(INTEGRITY);
      const figures = tests.map((t) => {
        const hpl = t === INTEGRITY;
        const chart = new StripChart({
          label: hpl ? "HPL (m)" : "statistic",
          thresholdLabel: hpl ? "HAL" : "threshold",
          onZoom: (t0, t1) => this.setRange([t0, t1]),
          onReset: () => this.setRange(null),
        });
        chart.canvas.dataset.session = s.id;
        chart.canvas.dataset.monitor = m.name;
        chart.canvas.dataset.test = hpl ? "hpl" : t;
        chart.setSeries(s.seriesFor(m.name, t));
        chart.setRange(this.range);
        chart.setLog(this.log);
        const b = hpl
          ? el("span", { class: "availability", "data-kind": "availability", "data-monitor": m.name })
          : badge(null, { "data-kind": "test", "data-monitor": m.name, "data-test": t });
        const value = el("span", { class: "num muted" });
        const consistency = el("span", { class: "consistency", "data-kind": "consistency", "data-monitor": m.name, "data-test": t });
        const caption = el("figcaption", null,
          el("strong", null, hpl ? "HPL vs HAL" : t), " ", b, " ", value, " ", consistency);
        const note = hpl ? el("p", { class: "muted note" },
          "Integrity availability, not a fault: amber while the filter converges from its initial covariance, red while the HPL is above the HAL.") : null;
        this.charts.push({ chart, monitor: m.name, test: t, badge: b, value, consistency, hpl });
        return el("figure", { class: "strip" + (hpl ? " hpl" : "") }, caption, chart.el, note);
      });
      const policy = el("span", { class: "muted policy" });
      const controlsSlot = el("div", { class: "controls-slot" });
      const toggle = el("button", { type: "button", "aria-expanded": "false", "data-control": "toggle", "data-monitor": m.name, "data-needs": "operate" }, "Threshold & policy\u2026");
      toggle.addEventListener("click", () => {
        const open = toggle.getAttribute("aria-expanded") !== "true";
        toggle.setAttribute("aria-expanded", String(open));
        if (open) controlsSlot.replaceChildren(new ThresholdControls(s.id, m.name, () => this.live.refresh(s.id)).el);
        else controlsSlot.replaceChildren();
      });
      const extra = [];
      if (m.type === "federated") {
        const chart = new TrackChart();
        chart.canvas.dataset.session = s.id;
        chart.canvas.dataset.monitor = m.name;
        const track = s.trackFor(m.name);
        chart.setTrack(track);
        const value = el("span", { class: "num muted" });
        const imu = onImu(m);
        if (imu) {
          chart.canvas.setAttribute("aria-label", "the mechanized solution's track, east and north in metres");
          chart.emptyText = "no solution until the strapdown is aligned\u2026";
        }
        // On raw IMU: the alignment state beside the track, filled by fillHead as stats arrive.
        const alignment = imu ? el("span", { class: "alignment", "data-kind": "alignment", "data-monitor": m.name }) : null;
        this.tracks.push({ chart, track, value, alignment, monitor: m.name });
        extra.push(el("figure", { class: "strip track" },
          el("figcaption", null, el("strong", null, "Track (local ENU, m)"), " ", alignment, " ", value),
          chart.el,
          el("p", { class: "muted note" },
            (imu
              ? "The mechanized solution (the monitor's own strapdown on the raw IMU, corrected in closed loop, so it is also the INS), "
              : "Corrected solution vs raw INS, ") +
            "east/north metres from the first point received. " +
            "Sampled from the session's stats messages (\u2264 20 per second, so a faster INS is thinned); " +
            "the last 20,000 points are kept." +
            (imu ? " No solution, no tests and no protection level until aligned." : ""))));
      }
      if (m.type === "gnss") {
        const panel = new GnssPanel(s.id, m.name, s.gnssFor(m.name), s.seriesFor(m.name, INTEGRITY));
        panel.setRange(this.range);
        this.gnss.push(panel);
        extra.push(...panel.figures);
      }
      const wide = tests.length > 1 || extra.length > 0;
      return el("section", { class: "card monitor" + (wide ? " wide" : ""), "data-monitor": m.name },
        el("div", { class: "monitor-head" },
          el("h3", null, m.name, " ", el("span", { class: "muted" }, m.type || "")), policy, toggle),
        controlsSlot,
        el("div", { class: "strips" }, ...figures, ...extra));
    });
    this.body.replaceChildren(...cards);
    this.policyCells = new Map(monitors.map((m, i) => [m.name, cards[i].querySelector(".policy")]));
  }

  fillHead(s, monitors) {
    for (const p of this.gnss) p.fill(monitors.find((x) => x.name === p.monitor));
    for (const tc of this.tracks) {
      if (!tc.alignment) continue;
      const state = alignmentOf(monitors.find((x) => x.name === tc.monitor) || {}) || "aligning";
      if (tc.alignment.dataset.state !== state) tc.alignment.dataset.state = state;
      setText(tc.alignment, ALIGNMENT_TEXT[state]);
    }
    for (const m of monitors) {
      const cell = this.policyCells && this.policyCells.get(m.name);
      if (cell && m.spec) {
        const level = m.spec.alarm_level || (s.info && s.info.alarm_level);
        setText(cell, [policyLevelText(m.spec.policy, level), isNum(m.spec.p_fa) ? "p_fa " + m.spec.p_fa : null,
          isNum(m.spec.threshold) ? "threshold " + fmtNum(m.spec.threshold) : null].filter(Boolean).join(" \u00b7 "));
      }
    }
    for (const c of this.charts) {
      const m = monitors.find((x) => x.name === c.monitor);
      if (c.hpl) {
        const i = m && m.live && m.live.integrity;
        const state = i ? i.state : "unknown";
        if (c.badge.dataset.state !== state) c.badge.dataset.state = state;
        setText(c.badge, state);
        // A null level is not yet known (an imu monitor aligning): a dash, no unit.
        const pl = isNum(i && i.protection_level) ? fmtNum(i.protection_level) + " m" : "\u2014";
        setText(c.value, i ? "HPL " + pl + " / HAL " + fmtNum(i.alert_limit) + " m \u00b7 unavailable " +
          fmtNum(i.time_s.unavailable) + " s, converging " + fmtNum(i.time_s.converging) + " s" : "");
        continue;
      }
      const ts = m && m.tests[c.test];
      setBadge(c.badge, ts && ts.state);
      setText(c.value, ts && isNum(ts.last) ? "last " + fmtNum(ts.last) + " / " + fmtNum(ts.threshold) + " (ratio " + fmtRatio(ts.last_test_ratio) + ")" : "");
      const cons = ts && ts.consistency;
      setText(c.consistency, consistencyText(cons));
      const flag = (cons && cons.flag) || "";
      if (c.consistency.dataset.flag !== flag) c.consistency.dataset.flag = flag;
      c.consistency.title = cons ? "Consistency of the normalised innovation over the last " + cons.samples +
        " healthy epochs: NIS mean " + fmtNum(cons.nis_mean) + " (bounds " + fmtNum(cons.nis_bounds[0]) + "\u2013" + fmtNum(cons.nis_bounds[1]) +
        "), lag-1 autocorrelation bound \u00b1" + fmtNum(cons.autocorr_bound) : "";
    }
    const st = s.stats;
    setText(this.facts, st
      ? (st.connected ? "stream connected" : "stream not connected") + " \u00b7 " + st.epochs + " epochs \u00b7 t " + fmtT(st.last_t) + " s \u00b7 events " + s.liveText()
      : "events " + s.liveText());
    this.downloadBtn.hidden = !(s.info && s.info.record);
  }

  fillAlarms() {
    const rows = this.live.recentAlarms.filter((a) => a.session === this.id).slice(0, SESSION_ALARMS).map((a) => {
      const cleared = a.cleared_t !== null && a.cleared_t !== undefined;
      // Jumps the charts to a minute around the alarm.
      const show = el("button", { type: "button", class: "link", "data-control": "show-alarm", title: "Show this moment in the charts" }, fmtClock(a.raised_at_ms));
      show.addEventListener("click", () => {
        this.setRange([a.t - 30, a.t + 30]);
        this.body.scrollIntoView({ behavior: "smooth", block: "start" });
      });
      return el("tr", { "data-alarm-id": a.id, "data-severity": a.severity || "alarm", class: cleared ? "cleared" : null },
        el("td", null, show), el("td", null, severityTag(a.severity)), el("td", null, a.monitor), el("td", null, a.test),
        el("td", null, badge(a.state)), el("td", { class: "num" }, fmtT(a.t)),
        el("td", { class: "num" }, fmtNum(a.statistic) + " / " + fmtNum(a.threshold)),
        el("td", { class: "num" }, fmtRatio(a.test_ratio)),
        el("td", null, cleared ? "at t " + fmtT(a.cleared_t) : "active"));
    });
    this.alarmBody.replaceChildren(...rows);
    if (!rows.length) this.alarmBody.append(el("tr", null, el("td", { colspan: 9, class: "muted" }, "No alarms or warnings for this session.")));
  }
}
