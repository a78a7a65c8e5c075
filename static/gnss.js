// gnss.js — the figures a gnss monitor (pseudorange RAIM/FDE) adds to its card
// in the session view: sky plot, protection levels against alert limits,
// residuals per satellite and the Stanford diagram, each with a caption, the
// latest values and a short note on how to read it. The canvases are drawn by
// gnss-charts.js; the session view calls draw(), fill() and setRange().

import { el, setText, fmtNum, fmtT } from "./dom.js";
import { SkyPlot, PlChart, ResidualChart, StanfordChart, SAT_STYLE, satState } from "./gnss-charts.js";

const GLYPH = { circle: "\u25cf", ring: "\u25cb", triangle: "\u25b2", cross: "\u2715" };

/** A legend of the satellite states: glyph, colour and word. */
function satLegend() {
  return el("span", { class: "legend sat-legend" }, ...Object.values(SAT_STYLE).map((s) =>
    el("span", null, el("span", { class: "glyph", style: "color:" + s.color, "aria-hidden": "true" }, GLYPH[s.shape]), " " + s.label)));
}

export class GnssPanel {
  /**
   * `history` is the monitor's GnssHistory, `bands` its integrity Series (for
   * the availability bands of the PL chart).
   */
  constructor(session, monitor, history, bands) {
    this.monitor = monitor;
    this.history = history;
    this.sky = new SkyPlot();
    this.pl = new PlChart();
    this.residuals = new ResidualChart();
    this.stanford = new StanfordChart();
    this.charts = [[this.sky, "sky"], [this.pl, "pl"], [this.residuals, "residuals"], [this.stanford, "stanford"]];
    for (const [c, plot] of this.charts) {
      c.setHistory(history);
      c.canvas.dataset.session = session;
      c.canvas.dataset.monitor = monitor;
      c.canvas.dataset.plot = plot;
    }
    this.pl.setBands(bands);
    const value = (field) => el("span", { class: "num muted", "data-field": field, "data-monitor": monitor });
    this.skyValue = value("satellites");
    this.availability = el("span", { class: "availability", "data-kind": "availability", "data-monitor": monitor });
    this.hplValue = value("hpl");
    this.plValue = value("pl");
    this.residualValue = value("residuals");
    this.stanfordValue = value("stanford");
    const figure = (cls, title, chart, kids, note) => el("figure", { class: "strip gnss " + cls },
      el("figcaption", null, el("strong", null, title), " ", ...kids), chart.el, el("p", { class: "muted note" }, note));
    this.figures = [
      figure("pl", "HPL and VPL vs HAL and VAL", this.pl, [this.availability, " ", this.hplValue, " ", this.plValue],
        "Protection levels (solid: HPL blue, VPL purple) against the alert limits (dashed HAL, dotted VAL). " +
        "Availability, not an alarm: red while a level is above its limit, the position is then not to be used for the " +
        "operation; the RAIM test (the \u03c7\u00b2 of the weighted residuals) is what raises alarms."),
      figure("sky", "Sky plot", this.sky, [this.skyValue],
        [satLegend(), el("br"), "Latest epoch: zenith at the centre, rings at elevation 0\u00b0, 30\u00b0, 60\u00b0, north up, azimuth clockwise."]),
      figure("residuals", "Residuals per satellite", this.residuals, [this.residualValue],
        "Latest epoch: the normalised residual w (residual over its \u03c3) when the server sends it, else the post-fit " +
        "residual in metres; coloured as in the sky plot. Satellites below the mask have none. No per-satellite " +
        "threshold is drawn: the test is on the \u03c7\u00b2 of all of them."),
      figure("stanford", "Stanford diagram", this.stanford, [this.stanfordValue],
        "Each epoch with a truth position: error HPE (x) against HPL (y), log axes, the dashed lines are the HAL. " +
        "Nominal: HPE \u2264 HPL \u2264 HAL. MI (misleading information): HPE > HPL while available. " +
        "HMI (hazardously misleading): HPE > HAL while HPL \u2264 HAL. Unavailable: HPL > HAL. " +
        "Darker cells hold more epochs; the last 6,000 epochs are kept."),
    ];
  }

  setRange(range) { this.pl.setRange(range); }
  invalidate() { for (const [c] of this.charts) c.invalidate(); }

  /** Redraws what changed; refreshes the figures' value texts when the data did. */
  draw() {
    let changed = false;
    for (const [c] of this.charts) if (c.draw()) changed = true;
    if (changed) this.fillValues();
  }

  fillValues() {
    const snap = this.history.latest;
    if (!snap) return;
    const sats = snap.satellites || [];
    const excluded = new Set(snap.excluded || []);
    const used = sats.filter((s) => satState(s, excluded) === "used").length;
    setText(this.skyValue, sats.length + " tracked \u00b7 " + used + " used" +
      (excluded.size ? " \u00b7 excluded " + [...excluded].join(", ") : "") + " \u00b7 t " + fmtT(snap.t) + " s");
    setText(this.hplValue, "HPL " + fmtNum(snap.hpl) + " m / HAL " + fmtNum(snap.hal) + " m");
    // The number itself, for the browser test: empty when the epoch had no solution.
    this.hplValue.dataset.value = snap.hpl === null || snap.hpl === undefined ? "" : String(snap.hpl);
    setText(this.plValue, "VPL " + fmtNum(snap.vpl) + " m / VAL " +
      (snap.val === null || snap.val === undefined ? "not set" : fmtNum(snap.val) + " m") +
      (snap.dop ? " \u00b7 HDOP " + fmtNum(snap.dop.hdop) + " VDOP " + fmtNum(snap.dop.vdop) : " \u00b7 no solution"));
    const q = this.residuals.canvas.dataset.quantity;
    setText(this.residualValue, q && Number(this.residuals.canvas.dataset.points) ? this.residuals.canvas.dataset.points + " satellites \u00b7 " + (q === "w" ? "normalised w" : "metres") : "");
    const d = this.stanford.canvas.dataset;
    setText(this.stanfordValue, Number(d.points) ? d.points + " epochs \u00b7 MI " + d.mi + " \u00b7 HMI " + d.hmi +
      " \u00b7 unavailable " + d.unavailable + (snap.hpe !== null && snap.hpe !== undefined ? " \u00b7 latest HPE " + fmtNum(snap.hpe) + " m" : "") : "");
  }

  /** The availability badge, from the monitor's live integrity. */
  fill(m) {
    const i = m && m.live && m.live.integrity;
    const state = i ? i.state : "unknown";
    if (this.availability.dataset.state !== state) this.availability.dataset.state = state;
    setText(this.availability, state);
    this.availability.title = i && i.time_s ? "unavailable " + fmtNum(i.time_s.unavailable) + " s in this session" : "";
  }
}
