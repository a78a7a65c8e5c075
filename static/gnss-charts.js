// gnss-charts.js — the canvas figures of a gnss monitor (pseudorange RAIM/FDE):
// a sky plot of the latest epoch's satellites, HPL and VPL against HAL and VAL
// over time, the latest residual per satellite, and a Stanford diagram of
// HPE against HPL. Each reads a `GnssHistory` from live.js and redraws only
// when it holds a new epoch, the canvas changed size or the time range moved.
// Each canvas says what it drew in data attributes (the browser test reads them).

import { fmtNum, fmtT, isNum } from "./dom.js";
import { COLORS, ticks } from "./chart.js";

/** A satellite's colour and marker by state (shape too, so it reads without colour). */
export const SAT_STYLE = {
  used: { color: "#0a7d4f", shape: "circle", label: "used" },
  unused: { color: "#8c959f", shape: "ring", label: "not used" },
  suspect: { color: "#b07f00", shape: "triangle", label: "suspect" },
  isolated: { color: "#c62828", shape: "cross", label: "isolated or excluded" },
};
const PL_COLORS = { hpl: "#0b5cad", vpl: "#7b3fb5", hal: "#c62828", val: "#8a1c1c" };
const PAD = { left: 56, right: 10, top: 8, bottom: 22 };

/** A satellite's state this epoch: FDE's exclusion outranks its health word. */
export function satState(sat, excluded) {
  if (sat.health === "isolated" || excluded.has(sat.id)) return "isolated";
  if (sat.health === "suspect") return "suspect";
  return sat.used ? "used" : "unused";
}

function marker(g, shape, x, y, r) {
  g.beginPath();
  if (shape === "triangle") {
    g.moveTo(x, y - r * 1.2); g.lineTo(x + r * 1.1, y + r * 0.8); g.lineTo(x - r * 1.1, y + r * 0.8); g.closePath(); g.fill();
  } else if (shape === "cross") {
    g.lineWidth = 2.5;
    g.moveTo(x - r, y - r); g.lineTo(x + r, y + r); g.moveTo(x + r, y - r); g.lineTo(x - r, y + r); g.stroke();
  } else if (shape === "ring") {
    g.lineWidth = 1.5; g.arc(x, y, r, 0, 2 * Math.PI); g.stroke();
  } else {
    g.arc(x, y, r, 0, 2 * Math.PI); g.fill();
  }
}

/**
 * The common shell: a canvas in a wrapper, drawn by `paint(g, w, h)` when
 * `key()` changed. `paint` returns the data attributes to publish.
 */
class Figure {
  constructor(cls, label) {
    this.canvas = document.createElement("canvas");
    this.canvas.className = "chart " + cls;
    this.canvas.setAttribute("role", "img");
    this.canvas.setAttribute("aria-label", label);
    this.canvas.dataset.points = "0";
    this.el = document.createElement("div");
    this.el.className = "chart-wrap";
    this.el.append(this.canvas);
    this.history = null;
    this.drawnKey = "";
  }
  setHistory(h) { this.history = h; this.drawnKey = ""; }
  invalidate() { this.drawnKey = ""; }
  key() { return String(this.history ? this.history.version : 0); }

  /** Draws when something changed; returns true if it drew. */
  draw() {
    const c = this.canvas;
    const w = c.clientWidth, h = c.clientHeight;
    if (!w || !h) return false; // not laid out (hidden view)
    const key = this.key() + ":" + w + "x" + h;
    if (key === this.drawnKey) return false;
    this.drawnKey = key;
    const dpr = window.devicePixelRatio || 1;
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
      c.width = Math.round(w * dpr); c.height = Math.round(h * dpr);
    }
    const g = c.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, w, h);
    g.font = "11px system-ui, sans-serif";
    const out = this.paint(g, w, h);
    // Drop what the last frame published and this one did not (a field that no longer applies).
    for (const k of this.published || []) if (!(k in out)) delete c.dataset[k];
    for (const [k, v] of Object.entries(out)) c.dataset[k] = String(v);
    this.published = Object.keys(out);
    return true;
  }

  waiting(g, w, h, text) {
    g.fillStyle = COLORS.axis; g.textAlign = "left"; g.textBaseline = "middle";
    g.fillText(text, PAD.left + 8, h / 2);
  }
}

/** Polar sky plot: zenith at the centre, the horizon on the rim, north up, azimuth clockwise. */
export class SkyPlot extends Figure {
  constructor() { super("sky-chart", "sky plot of the latest epoch's satellites, north up, zenith at the centre"); }

  paint(g, w, h) {
    const snap = this.history && this.history.latest;
    const R = Math.max(10, Math.min(w, h) / 2 - 20);
    const cx = w / 2, cy = h / 2;
    const rOf = (elDeg) => R * (90 - elDeg) / 90;
    g.strokeStyle = COLORS.grid; g.lineWidth = 1; g.fillStyle = COLORS.axis;
    for (const e of [0, 30, 60]) {
      g.beginPath(); g.arc(cx, cy, rOf(e), 0, 2 * Math.PI); g.stroke();
      g.textAlign = "left"; g.textBaseline = "top"; // inside the ring, clear of the "N"
      g.fillText(e + "\u00b0", cx + 3, cy - rOf(e) + 2);
    }
    for (let az = 0; az < 360; az += 30) {
      const a = az * Math.PI / 180;
      g.beginPath(); g.moveTo(cx, cy); g.lineTo(cx + R * Math.sin(a), cy - R * Math.cos(a)); g.stroke();
    }
    g.textAlign = "center"; g.textBaseline = "middle"; g.font = "bold 12px system-ui, sans-serif";
    for (const [txt, az] of [["N", 0], ["E", 90], ["S", 180], ["W", 270]]) {
      const a = az * Math.PI / 180;
      g.fillText(txt, cx + (R + 11) * Math.sin(a), cy - (R + 11) * Math.cos(a));
    }
    g.font = "11px system-ui, sans-serif";
    if (!snap) { this.waiting(g, w, h, "waiting for the first epoch with pseudoranges\u2026"); return { points: 0 }; }
    const excluded = new Set(snap.excluded || []);
    const counts = { used: 0, unused: 0, suspect: 0, isolated: 0 };
    let drawn = 0;
    for (const sat of snap.satellites || []) {
      if (!isNum(sat.el) || !isNum(sat.az) || sat.el < 0) continue; // below the horizon: not on a sky plot
      const state = satState(sat, excluded), st = SAT_STYLE[state];
      const r = rOf(Math.min(90, sat.el)), a = sat.az * Math.PI / 180;
      const x = cx + r * Math.sin(a), y = cy - r * Math.cos(a);
      g.fillStyle = st.color; g.strokeStyle = st.color;
      marker(g, st.shape, x, y, 5);
      g.fillStyle = COLORS.hover; g.textAlign = "left"; g.textBaseline = "middle";
      g.fillText(String(sat.id), x + 7, y);
      counts[state]++; drawn++;
    }
    return { points: drawn, used: counts.used, suspect: counts.suspect, isolated: counts.isolated, t: snap.t };
  }
}

/**
 * HPL and VPL against HAL and VAL over time, on the session's shared time
 * range, with the monitor's availability bands (amber converging, red
 * unavailable) from its integrity series. A gap where an epoch had no value.
 */
export class PlChart extends Figure {
  constructor() {
    super("pl-chart", "horizontal and vertical protection levels against their alert limits");
    this.range = null; this.bandsOf = null;
  }
  setRange(range) { this.range = range; this.drawnKey = ""; }
  /** `series` (a live.js Series) gives the availability bands. */
  setBands(series) { this.bandsOf = series; this.drawnKey = ""; }
  key() {
    const b = this.bandsOf ? this.bandsOf.transitions.length + "/" + this.bandsOf.length : "";
    return super.key() + ":" + (this.range ? this.range.join(",") : "") + ":" + b;
  }

  paint(g, w, h) {
    const H = this.history, n = H ? H.length : 0;
    const plotW = w - PAD.left - PAD.right, plotH = h - PAD.top - PAD.bottom;
    if (!n) { this.waiting(g, w, h, "waiting for the first epoch\u2026"); return { points: 0 }; }
    let t0 = this.range ? this.range[0] : H.t[0], t1 = this.range ? this.range[1] : H.t[n - 1];
    if (!(t1 > t0)) { t0 -= 0.5; t1 += 0.5; }
    const keys = ["hpl", "vpl", "hal", "val"];
    let hi = 0, visible = [];
    for (let i = 0; i < n; i++) {
      if (H.t[i] < t0 || H.t[i] > t1) continue;
      visible.push(i);
      for (const k of keys) { const v = H[k][i]; if (v !== null && v > hi) hi = v; }
    }
    if (!(hi > 0)) hi = 1;
    hi *= 1.08;
    const xOf = (t) => PAD.left + ((t - t0) / (t1 - t0)) * plotW;
    const yOf = (v) => PAD.top + plotH - (v / hi) * plotH;

    g.save();
    g.beginPath(); g.rect(PAD.left, PAD.top, plotW, plotH); g.clip();
    for (const b of this.bandsOf ? this.bandsOf.bands() : []) {
      if (b.t1 < t0 || b.t0 > t1) continue;
      const xa = xOf(Math.max(b.t0, t0)), xb = xOf(Math.min(b.t1, t1));
      g.fillStyle = COLORS[b.state]; g.fillRect(xa, PAD.top, Math.max(1, xb - xa), plotH);
    }
    g.restore();

    g.strokeStyle = COLORS.grid; g.fillStyle = COLORS.axis; g.lineWidth = 1;
    g.textAlign = "right"; g.textBaseline = "middle";
    for (const v of ticks(0, hi, 4)) {
      const y = Math.round(yOf(v)) + 0.5;
      g.beginPath(); g.moveTo(PAD.left, y); g.lineTo(PAD.left + plotW, y); g.stroke();
      g.fillText(fmtNum(v), PAD.left - 4, y);
    }
    g.textAlign = "center"; g.textBaseline = "top";
    for (const t of ticks(t0, t1, Math.max(2, Math.floor(plotW / 90)))) {
      const x = Math.round(xOf(t)) + 0.5;
      g.beginPath(); g.moveTo(x, PAD.top); g.lineTo(x, PAD.top + plotH); g.stroke();
      g.fillText(fmtT(t) + " s", x, PAD.top + plotH + 5);
    }

    g.save();
    g.beginPath(); g.rect(PAD.left, PAD.top, plotW, plotH); g.clip();
    const dots = visible.length <= plotW / 6; // few epochs: mark each one
    const styles = { hpl: [1.6, []], vpl: [1.6, []], hal: [1.5, [5, 3]], val: [1.5, [2, 3]] };
    for (const k of keys) {
      const [lw, dash] = styles[k];
      g.strokeStyle = PL_COLORS[k]; g.fillStyle = PL_COLORS[k]; g.lineWidth = lw; g.setLineDash(dash);
      g.beginPath();
      let pen = false;
      for (const i of visible) {
        const v = H[k][i];
        if (v === null) { pen = false; continue; } // no solution, or no VAL: a gap
        const x = xOf(H.t[i]), y = yOf(v);
        if (pen) g.lineTo(x, y); else g.moveTo(x, y);
        pen = true;
      }
      g.stroke();
      g.setLineDash([]);
      if (dots && (k === "hpl" || k === "vpl")) {
        for (const i of visible) if (H[k][i] !== null) { g.beginPath(); g.arc(xOf(H.t[i]), yOf(H[k][i]), 2.5, 0, 2 * Math.PI); g.fill(); }
      }
    }
    g.restore();
    g.strokeStyle = COLORS.axis; g.lineWidth = 1;
    g.strokeRect(PAD.left + 0.5, PAD.top + 0.5, plotW, plotH);

    let points = 0;
    for (const i of visible) if (H.hpl[i] !== null) points++;
    return { points, last: H.hpl[n - 1] ?? "", lastVpl: H.vpl[n - 1] ?? "" };
  }
}

/**
 * The latest epoch's residual per satellite: the normalised residual `w` when
 * the epoch carries it, the post-fit residual in metres otherwise. Bars
 * coloured by the satellite's state; satellites without a residual (below
 * the mask) are left out.
 */
export class ResidualChart extends Figure {
  constructor() { super("residual-chart", "latest residual per satellite"); }

  paint(g, w, h) {
    const snap = this.history && this.history.latest;
    const P = { left: PAD.left, right: PAD.right, top: PAD.top, bottom: 40 };
    const plotW = w - P.left - P.right, plotH = h - P.top - P.bottom;
    if (!snap) { this.waiting(g, w, h, "waiting for the first epoch\u2026"); return { points: 0 }; }
    const sats = (snap.satellites || []).slice().sort((a, b) => String(a.id).localeCompare(String(b.id)));
    const quantity = sats.some((s) => isNum(s.w)) ? "w" : "residual";
    const bars = sats.filter((s) => isNum(s[quantity]));
    if (!bars.length) { this.waiting(g, w, h, "no residuals this epoch (no solution)"); return { points: 0, quantity }; }
    let m = 1; // at least ±1 (σ or m) so small residuals do not fill the plot
    for (const s of bars) m = Math.max(m, Math.abs(s[quantity]));
    m *= 1.1;
    const yOf = (v) => P.top + plotH / 2 - (v / m) * (plotH / 2);
    g.strokeStyle = COLORS.grid; g.fillStyle = COLORS.axis; g.lineWidth = 1;
    g.textAlign = "right"; g.textBaseline = "middle";
    for (const v of ticks(-m, m, 4)) {
      const y = Math.round(yOf(v)) + 0.5;
      g.beginPath(); g.moveTo(P.left, y); g.lineTo(P.left + plotW, y); g.stroke();
      g.fillText(fmtNum(v), P.left - 4, y);
    }
    g.save();
    g.translate(12, P.top + plotH / 2); g.rotate(-Math.PI / 2); g.textAlign = "center"; g.textBaseline = "middle";
    g.fillText(quantity === "w" ? "w (normalised)" : "residual (m)", 0, 0);
    g.restore();
    const excluded = new Set(snap.excluded || []);
    const slot = plotW / bars.length, bw = Math.max(2, Math.min(24, slot * 0.7));
    const y0 = yOf(0);
    bars.forEach((s, k) => {
      const x = P.left + slot * (k + 0.5), y = yOf(s[quantity]);
      const st = SAT_STYLE[satState(s, excluded)];
      g.fillStyle = st.color;
      if (st.shape === "ring") { g.strokeStyle = st.color; g.lineWidth = 1.5; g.strokeRect(x - bw / 2, Math.min(y, y0), bw, Math.max(1, Math.abs(y - y0))); }
      else g.fillRect(x - bw / 2, Math.min(y, y0), bw, Math.max(1, Math.abs(y - y0)));
      g.save();
      g.translate(x, P.top + plotH + 4); g.rotate(-Math.PI / 4);
      g.fillStyle = COLORS.axis; g.textAlign = "right"; g.textBaseline = "middle";
      g.fillText(String(s.id), 0, 0);
      g.restore();
    });
    g.strokeStyle = COLORS.axis; g.lineWidth = 1;
    g.beginPath(); g.moveTo(P.left, Math.round(y0) + 0.5); g.lineTo(P.left + plotW, Math.round(y0) + 0.5); g.stroke();
    g.strokeRect(P.left + 0.5, P.top + 0.5, plotW, plotH);
    return { points: bars.length, quantity, t: snap.t };
  }
}

/** Cells of the Stanford diagram's histogram, per axis. */
const STANFORD_BINS = 60;

/**
 * The Stanford diagram: HPE (x) against HPL (y) on equal log axes, one cell
 * count per bin (the history is bounded, so is the cost). Each epoch falls in
 * exactly one region, against its own HAL: unavailable (HPL > HAL), HMI
 * (HPE > HAL ≥ HPL), MI (HPL < HPE ≤ HAL) or nominal (HPE ≤ HPL ≤ HAL).
 */
export class StanfordChart extends Figure {
  constructor() { super("stanford-chart", "Stanford diagram: horizontal position error against horizontal protection level"); }

  paint(g, w, h) {
    const H = this.history, n = H ? H.length : 0;
    const idx = [];
    let lo = Infinity, hi = 0, hal = null;
    for (let i = 0; i < n; i++) {
      if (H.hal[i] !== null) hal = H.hal[i];
      const e = H.hpe[i], p = H.hpl[i];
      if (e === null || p === null || !(e > 0) || !(p > 0)) continue;
      idx.push(i);
      lo = Math.min(lo, e, p); hi = Math.max(hi, e, p);
    }
    if (!idx.length) {
      this.waiting(g, w, h, n ? "no HPE: the epochs carry no truth position" : "waiting for the first epoch\u2026");
      return { points: 0 };
    }
    if (hal !== null) { lo = Math.min(lo, hal); hi = Math.max(hi, hal); }
    // Whole decades, at least two, with the HAL well inside.
    let d0 = Math.floor(Math.log10(lo * 0.8)), d1 = Math.ceil(Math.log10(hi * 1.5));
    if (d1 - d0 < 2) d0 = d1 - 2;
    const side = Math.min(w - PAD.left - PAD.right, h - PAD.top - PAD.bottom - 8);
    const x0 = PAD.left, y0 = PAD.top;
    const f = (v) => (Math.log10(v) - d0) / (d1 - d0);
    const xOf = (v) => x0 + f(v) * side, yOf = (v) => y0 + side - f(v) * side;

    // Regions under everything, from the latest HAL.
    if (hal !== null && hal > 0) {
      const xh = xOf(hal), yh = yOf(hal);
      g.fillStyle = "rgba(140, 149, 159, 0.18)"; g.fillRect(x0, y0, side, yh - y0);               // HPL > HAL
      g.fillStyle = "rgba(210, 59, 59, 0.18)"; g.fillRect(xh, yh, x0 + side - xh, y0 + side - yh); // HPE > HAL ≥ HPL
      g.fillStyle = "rgba(212, 155, 0, 0.18)";                                                     // HPL < HPE ≤ HAL
      g.beginPath(); g.moveTo(x0, y0 + side); g.lineTo(xh, yh); g.lineTo(xh, y0 + side); g.closePath(); g.fill();
    }
    g.strokeStyle = COLORS.grid; g.fillStyle = COLORS.axis; g.lineWidth = 1;
    for (let d = d0; d <= d1; d++) {
      const v = Math.pow(10, d), x = Math.round(xOf(v)) + 0.5, y = Math.round(yOf(v)) + 0.5;
      g.beginPath(); g.moveTo(x, y0); g.lineTo(x, y0 + side); g.moveTo(x0, y); g.lineTo(x0 + side, y); g.stroke();
      g.textAlign = "center"; g.textBaseline = "top"; g.fillText(fmtNum(v), x, y0 + side + 4);
      g.textAlign = "right"; g.textBaseline = "middle"; g.fillText(fmtNum(v), x0 - 4, y);
    }
    // The diagonal HPE = HPL, and the HAL on both axes.
    g.strokeStyle = COLORS.axis; g.setLineDash([3, 3]);
    g.beginPath(); g.moveTo(x0, y0 + side); g.lineTo(x0 + side, y0); g.stroke();
    g.setLineDash([]);
    if (hal !== null && hal > 0) {
      g.strokeStyle = COLORS.threshold; g.setLineDash([5, 3]); g.lineWidth = 1.5;
      g.beginPath(); g.moveTo(xOf(hal), y0); g.lineTo(xOf(hal), y0 + side); g.moveTo(x0, yOf(hal)); g.lineTo(x0 + side, yOf(hal)); g.stroke();
      g.setLineDash([]); g.lineWidth = 1;
    }

    // Histogram: one count per cell, darker for more epochs (log scale).
    const cells = new Map();
    const regions = { nominal: 0, mi: 0, hmi: 0, unavailable: 0 };
    const cell = (v) => Math.min(STANFORD_BINS - 1, Math.max(0, Math.floor(f(v) * STANFORD_BINS)));
    for (const i of idx) {
      const e = H.hpe[i], p = H.hpl[i], a = H.hal[i] !== null ? H.hal[i] : hal;
      if (a !== null && p > a) regions.unavailable++;
      else if (a !== null && e > a) regions.hmi++;
      else if (e > p) regions.mi++;
      else regions.nominal++;
      const k = cell(e) * STANFORD_BINS + cell(p);
      cells.set(k, (cells.get(k) || 0) + 1);
    }
    let most = 1;
    for (const c of cells.values()) most = Math.max(most, c);
    const cs = side / STANFORD_BINS;
    for (const [k, c] of cells) {
      const cx = Math.floor(k / STANFORD_BINS), cy = k % STANFORD_BINS;
      const shade = 0.35 + 0.65 * Math.log(1 + c) / Math.log(1 + most);
      g.fillStyle = "rgba(11, 92, 173, " + shade.toFixed(3) + ")";
      g.fillRect(x0 + cx * cs, y0 + side - (cy + 1) * cs, Math.max(2, cs), Math.max(2, cs));
    }
    g.strokeStyle = COLORS.axis; g.strokeRect(x0 + 0.5, y0 + 0.5, side, side);

    // Region labels with their counts, and the axis names beside the square.
    g.font = "bold 11px system-ui, sans-serif"; g.fillStyle = COLORS.hover;
    if (hal !== null && hal > 0) {
      const xh = xOf(hal), yh = yOf(hal);
      g.textAlign = "center"; g.textBaseline = "top";
      g.fillText("unavailable " + regions.unavailable, x0 + side / 2, y0 + 4);
      g.textAlign = "right"; g.textBaseline = "bottom";
      g.fillText("HMI " + regions.hmi, x0 + side - 4, y0 + side - 4);
      g.textAlign = "left";
      g.fillText("MI " + regions.mi, Math.max(x0 + 4, xh - (xh - x0) * 0.45), y0 + side - 4);
      g.textAlign = "left"; g.textBaseline = "top";
      g.fillText("nominal " + regions.nominal, x0 + 4, yh + 4);
    }
    g.font = "11px system-ui, sans-serif"; g.fillStyle = COLORS.axis; g.textAlign = "left"; g.textBaseline = "middle";
    const lx = x0 + side + 10;
    if (lx + 80 < w) {
      g.fillText("x: HPE (m)", lx, y0 + 10);
      g.fillText("y: HPL (m)", lx, y0 + 26);
      g.fillText("- - HAL " + fmtNum(hal), lx, y0 + 42);
      g.fillText("\u00b7\u00b7 HPE = HPL", lx, y0 + 58);
    }
    return { points: idx.length, bins: cells.size, nominal: regions.nominal, mi: regions.mi, hmi: regions.hmi, unavailable: regions.unavailable };
  }
}
