// chart.js — a canvas strip chart of one test: statistic against threshold
// over epoch time, with shaded bands where the test was suspect or isolated.
// Drawn by hand (no library): downsampled to min/max per pixel column so a
// 6000-point history costs the same as the chart is wide; redrawn only when
// the data, the time range or the hover position changed. Also TrackChart:
// a federated monitor's corrected and raw INS tracks in local ENU metres (one
// track, the mechanized solution, for a monitor on raw IMU).

import { fmtNum, fmtT, isNum } from "./dom.js";

export const COLORS = {
  line: "#0b5cad", threshold: "#c62828", grid: "#e3e7ec", axis: "#57606a",
  suspect: "rgba(212, 155, 0, 0.22)", isolated: "rgba(210, 59, 59, 0.22)", hover: "#1b1f24",
};
const PAD = { left: 56, right: 10, top: 8, bottom: 22 };

/** Index of the first element of sorted `a` that is ≥ x. */
function lowerBound(a, x) {
  let lo = 0, hi = a.length;
  while (lo < hi) { const mid = (lo + hi) >> 1; if (a[mid] < x) lo = mid + 1; else hi = mid; }
  return lo;
}

/** "Nice" tick values covering [lo, hi], about `n` of them. */
export function ticks(lo, hi, n) {
  const span = hi - lo;
  if (!(span > 0)) return [lo];
  const raw = span / n;
  const mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((k) => k * mag).find((s) => s >= raw) || 10 * mag;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(Number(v.toPrecision(12)));
  return out;
}

export class StripChart {
  /**
   * `opts.label` names the statistic, `opts.thresholdLabel` the limit
   * ("threshold", or "HAL" for the HPL chart); `opts.onZoom(t0, t1)` is called
   * when the user drags out a time range, `opts.onReset()` on double-click.
   */
  constructor(opts) {
    this.opts = opts;
    this.canvas = document.createElement("canvas");
    this.canvas.className = "chart";
    this.canvas.setAttribute("role", "img");
    this.canvas.setAttribute("aria-label", opts.label + " against " + opts.thresholdLabel);
    this.canvas.dataset.points = "0";
    this.tip = document.createElement("div");
    this.tip.className = "chart-tip";
    this.tip.hidden = true;
    this.el = document.createElement("div");
    this.el.className = "chart-wrap";
    this.el.append(this.canvas, this.tip);
    this.series = null;
    this.range = null;    // [t0, t1] when zoomed
    this.log = false;
    this.hoverX = null;
    this.drag = null;
    this.dirty = true;
    this.layout = null;
    this.bindPointer();
  }

  setSeries(series) { this.series = series; this.dirty = true; }
  setRange(range) { this.range = range; this.dirty = true; }
  setLog(on) { if (this.log !== on) { this.log = on; this.dirty = true; } }
  invalidate() { this.dirty = true; }

  bindPointer() {
    const c = this.canvas;
    const x = (ev) => ev.clientX - c.getBoundingClientRect().left;
    c.addEventListener("mousemove", (ev) => {
      this.hoverX = x(ev);
      if (this.drag) this.drag.x1 = this.hoverX;
      this.dirty = true;
    });
    c.addEventListener("mouseleave", () => { this.hoverX = null; this.drag = null; this.tip.hidden = true; this.dirty = true; });
    c.addEventListener("mousedown", (ev) => { this.drag = { x0: x(ev), x1: x(ev) }; });
    c.addEventListener("mouseup", () => {
      const d = this.drag;
      this.drag = null;
      if (!d || !this.layout || Math.abs(d.x1 - d.x0) < 5) return;
      const { tOf } = this.layout;
      const t0 = tOf(Math.min(d.x0, d.x1)), t1 = tOf(Math.max(d.x0, d.x1));
      if (this.opts.onZoom) this.opts.onZoom(t0, t1);
    });
    c.addEventListener("dblclick", () => { if (this.opts.onReset) this.opts.onReset(); });
  }

  /** Draws when something changed; returns true if it drew. */
  draw() {
    if (!this.dirty) return false;
    const c = this.canvas;
    const cssW = c.clientWidth, cssH = c.clientHeight;
    if (!cssW || !cssH) return false; // not laid out (hidden view)
    this.dirty = false;
    const dpr = window.devicePixelRatio || 1;
    if (c.width !== Math.round(cssW * dpr) || c.height !== Math.round(cssH * dpr)) {
      c.width = Math.round(cssW * dpr);
      c.height = Math.round(cssH * dpr);
    }
    const g = c.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, cssW, cssH);
    g.font = "11px system-ui, sans-serif";

    const s = this.series;
    const n = s ? s.length : 0;
    const plotW = cssW - PAD.left - PAD.right, plotH = cssH - PAD.top - PAD.bottom;
    if (n === 0) {
      g.fillStyle = COLORS.axis;
      g.fillText("waiting for data\u2026", PAD.left + 8, PAD.top + plotH / 2);
      c.dataset.points = "0";
      return true;
    }

    // Time range: the zoom, or everything we hold.
    let t0 = this.range ? this.range[0] : s.t[0];
    let t1 = this.range ? this.range[1] : s.t[n - 1];
    if (!(t1 > t0)) { t0 -= 0.5; t1 += 0.5; }
    const i0 = Math.max(0, lowerBound(s.t, t0) - 1);
    const i1 = Math.min(n, lowerBound(s.t, t1) + 1);

    // Value range over what is visible, threshold included so the limit always shows.
    let lo = Infinity, hi = -Infinity;
    for (let i = i0; i < i1; i++) {
      const v = s.v[i], th = s.thr[i];
      if (v < lo) lo = v; if (v > hi) hi = v;
      if (th < lo) lo = th; if (th > hi) hi = th;
    }
    const log = this.log;
    // Log scale: statistics are ≥ 0 but can be exactly 0; floor at 1e-3 of the largest value.
    const floor = log ? Math.max(hi * 1e-6, 1e-9) : 0;
    const f = log ? (v) => Math.log10(Math.max(v, floor)) : (v) => v;
    let ylo = log ? f(Math.max(lo, floor)) : Math.min(0, lo);
    let yhi = f(hi);
    if (!(yhi > ylo)) yhi = ylo + 1;
    yhi += (yhi - ylo) * 0.06;

    const xOf = (t) => PAD.left + ((t - t0) / (t1 - t0)) * plotW;
    const tOf = (x) => t0 + ((x - PAD.left) / plotW) * (t1 - t0);
    const yOf = (v) => PAD.top + plotH - ((f(v) - ylo) / (yhi - ylo)) * plotH;
    this.layout = { xOf, tOf, yOf, i0, i1 };

    // Bands first, under everything.
    g.save();
    g.beginPath(); g.rect(PAD.left, PAD.top, plotW, plotH); g.clip();
    for (const b of s.bands()) {
      if (b.t1 < t0 || b.t0 > t1) continue;
      const xa = xOf(Math.max(b.t0, t0)), xb = xOf(Math.min(b.t1, t1));
      g.fillStyle = COLORS[b.state];
      g.fillRect(xa, PAD.top, Math.max(1, xb - xa), plotH);
    }
    g.restore();

    // Grid and axes.
    g.strokeStyle = COLORS.grid; g.fillStyle = COLORS.axis; g.lineWidth = 1;
    const yTicks = log
      ? ticks(Math.ceil(ylo), Math.floor(yhi), 4).filter(Number.isInteger).map((e) => Math.pow(10, e))
      : ticks(ylo, yhi, 4);
    g.textAlign = "right"; g.textBaseline = "middle";
    for (const v of yTicks) {
      const y = yOf(v);
      if (y < PAD.top - 1 || y > PAD.top + plotH + 1) continue;
      g.beginPath(); g.moveTo(PAD.left, Math.round(y) + 0.5); g.lineTo(PAD.left + plotW, Math.round(y) + 0.5); g.stroke();
      g.fillText(fmtNum(v), PAD.left - 4, y);
    }
    g.textAlign = "center"; g.textBaseline = "top";
    for (const t of ticks(t0, t1, Math.max(2, Math.floor(plotW / 90)))) {
      const x = xOf(t);
      g.beginPath(); g.moveTo(Math.round(x) + 0.5, PAD.top); g.lineTo(Math.round(x) + 0.5, PAD.top + plotH); g.stroke();
      g.fillText(fmtT(t) + " s", x, PAD.top + plotH + 5);
    }

    g.save();
    g.beginPath(); g.rect(PAD.left, PAD.top, plotW, plotH); g.clip();
    // Threshold: a dashed step line (it changes when an operator edits it).
    g.strokeStyle = COLORS.threshold; g.setLineDash([5, 3]); g.lineWidth = 1.5;
    g.beginPath();
    for (let i = i0; i < i1; i++) {
      const x = xOf(s.t[i]), y = yOf(s.thr[i]);
      if (i === i0) g.moveTo(x, y);
      else { g.lineTo(x, yOf(s.thr[i - 1])); g.lineTo(x, y); }
    }
    g.stroke();
    g.setLineDash([]);

    // Statistic: every point when few, min/max per pixel column when many.
    g.strokeStyle = COLORS.line; g.lineWidth = 1.25;
    g.beginPath();
    let drawn = 0;
    if (i1 - i0 <= plotW * 2) {
      for (let i = i0; i < i1; i++) {
        const x = xOf(s.t[i]), y = yOf(s.v[i]);
        if (i === i0) g.moveTo(x, y); else g.lineTo(x, y);
        drawn++;
      }
    } else {
      let col = -1, cmin = 0, cmax = 0, first = true;
      const flush = () => {
        if (col < 0) return;
        const x = col + 0.5;
        if (first) { g.moveTo(x, yOf(cmin)); first = false; } else g.lineTo(x, yOf(cmin));
        g.lineTo(x, yOf(cmax));
        drawn += 2;
      };
      for (let i = i0; i < i1; i++) {
        const x = Math.floor(xOf(s.t[i])), v = s.v[i];
        if (x !== col) { flush(); col = x; cmin = v; cmax = v; }
        else { if (v < cmin) cmin = v; if (v > cmax) cmax = v; }
      }
      flush();
    }
    g.stroke();

    // Drag selection.
    if (this.drag) {
      g.fillStyle = "rgba(11, 92, 173, 0.12)";
      g.fillRect(Math.min(this.drag.x0, this.drag.x1), PAD.top, Math.abs(this.drag.x1 - this.drag.x0), plotH);
    }
    g.restore();
    g.strokeStyle = COLORS.axis;
    g.strokeRect(PAD.left + 0.5, PAD.top + 0.5, plotW, plotH);

    this.drawHover(g, plotH);
    // For tests and the curious: how many points this frame drew, and the last value.
    c.dataset.points = String(drawn);
    c.dataset.last = String(s.v[n - 1]);
    return true;
  }

  drawHover(g, plotH) {
    const s = this.series, L = this.layout;
    if (this.hoverX === null || !L || this.hoverX < PAD.left) { this.tip.hidden = true; return; }
    const t = L.tOf(this.hoverX);
    let i = lowerBound(s.t, t);
    if (i >= s.length || (i > 0 && t - s.t[i - 1] < s.t[i] - t)) i--;
    if (i < L.i0 || i >= L.i1 || i < 0) { this.tip.hidden = true; return; }
    const x = L.xOf(s.t[i]), y = L.yOf(s.v[i]);
    g.strokeStyle = COLORS.hover; g.lineWidth = 1;
    g.beginPath(); g.moveTo(Math.round(x) + 0.5, PAD.top); g.lineTo(Math.round(x) + 0.5, PAD.top + plotH); g.stroke();
    g.fillStyle = COLORS.hover;
    g.beginPath(); g.arc(x, y, 3, 0, 2 * Math.PI); g.fill();
    const ratio = s.thr[i] > 0 ? s.v[i] / s.thr[i] : NaN;
    this.tip.textContent = "t " + fmtT(s.t[i]) + " s \u00b7 " + this.opts.label + " " + fmtNum(s.v[i]) +
      " \u00b7 " + this.opts.thresholdLabel + " " + fmtNum(s.thr[i]) +
      (isNum(ratio) ? " \u00b7 ratio " + ratio.toFixed(2) : "") + " \u00b7 " + s.state[i];
    this.tip.hidden = false;
    const w = this.canvas.clientWidth;
    this.tip.style.left = Math.min(Math.max(0, x + 8), Math.max(0, w - 260)) + "px";
  }
}

const TRACK_COLORS = { solution: "#0a7d4f", ins: "#d9730d" };
const TRACK_PAD = { left: 56, right: 10, top: 8, bottom: 22 };

/**
 * The corrected track against the raw INS track, east/north metres from the
 * first point received (a `Track` from live.js). Equal scales on both axes so
 * a turn looks like a turn and a drift's direction reads true. Points closer
 * than a pixel to the last one drawn are skipped, so 20,000 points cost about
 * as much as the path is long on screen. When the INS track is the solution
 * (a monitor on raw IMU mechanizes it and feeds the correction back, or no
 * point has yet parted), only the solution is drawn, under one legend entry.
 */
export class TrackChart {
  constructor() {
    this.canvas = document.createElement("canvas");
    this.canvas.className = "chart track-chart";
    this.canvas.setAttribute("role", "img");
    this.canvas.setAttribute("aria-label", "corrected track against the raw INS track, east and north in metres");
    this.canvas.dataset.points = "0";
    this.el = document.createElement("div");
    this.el.className = "chart-wrap";
    this.el.append(this.canvas);
    this.track = null;
    this.drawnKey = "";
    /** What an empty plot says (a monitor on raw IMU has no position until aligned). */
    this.emptyText = "waiting for the first INS epoch\u2026";
  }

  setTrack(track) { this.track = track; this.drawnKey = ""; }
  invalidate() { this.drawnKey = ""; }

  /** Draws when the track or the canvas size changed; returns true if it drew. */
  draw() {
    const c = this.canvas;
    const cssW = c.clientWidth, cssH = c.clientHeight;
    if (!cssW || !cssH) return false; // not laid out (hidden view)
    const tr = this.track;
    const n = tr ? tr.length : 0;
    const key = (tr ? tr.version : 0) + ":" + cssW + "x" + cssH;
    if (key === this.drawnKey) return false;
    this.drawnKey = key;
    const dpr = window.devicePixelRatio || 1;
    if (c.width !== Math.round(cssW * dpr) || c.height !== Math.round(cssH * dpr)) {
      c.width = Math.round(cssW * dpr);
      c.height = Math.round(cssH * dpr);
    }
    const g = c.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, cssW, cssH);
    g.font = "11px system-ui, sans-serif";
    const P = TRACK_PAD;
    const plotW = cssW - P.left - P.right, plotH = cssH - P.top - P.bottom;
    if (n === 0) {
      g.fillStyle = COLORS.axis;
      g.fillText(this.emptyText, P.left + 8, P.top + plotH / 2);
      c.dataset.points = "0";
      return true;
    }

    // Extent of both tracks, then one scale (m per pixel) for both axes: the
    // tighter of the two fits, the other axis is centred with room to spare.
    let e0 = Infinity, e1 = -Infinity, n0 = Infinity, n1 = -Infinity;
    // One track when the INS is the solution: an identical line on top would only
    // hide it, and a second legend entry would suggest two tracks.
    const single = tr.mechanized || !tr.distinct;
    const lines = single
      ? [[tr.sE, tr.sN, TRACK_COLORS.solution, 4]]
      : [[tr.sE, tr.sN, TRACK_COLORS.solution, 4], [tr.iE, tr.iN, TRACK_COLORS.ins, 1.5]];
    for (const [E, N] of lines) {
      for (let i = 0; i < n; i++) {
        const e = E[i], nn = N[i];
        if (e < e0) e0 = e; if (e > e1) e1 = e;
        if (nn < n0) n0 = nn; if (nn > n1) n1 = nn;
      }
    }
    const span = Math.max(e1 - e0, n1 - n0, 1) * 1.12; // ≥ 1 m so a standing start still draws
    const scale = Math.min(plotW, plotH) / span;      // px per m
    const ec = (e0 + e1) / 2, nc = (n0 + n1) / 2;
    const cx = P.left + plotW / 2, cy = P.top + plotH / 2;
    const xOf = (e) => cx + (e - ec) * scale;
    const yOf = (v) => cy - (v - nc) * scale;

    // Grid in round metres, the same step on both axes.
    const step = ticks(0, Math.max(plotW, plotH) / scale, Math.max(2, Math.floor(Math.max(plotW, plotH) / 90)));
    const d = step.length > 1 ? step[1] - step[0] : 1;
    g.strokeStyle = COLORS.grid; g.fillStyle = COLORS.axis; g.lineWidth = 1;
    const eLo = ec - (plotW / 2) / scale, eHi = ec + (plotW / 2) / scale;
    const nLo = nc - (plotH / 2) / scale, nHi = nc + (plotH / 2) / scale;
    g.textAlign = "center"; g.textBaseline = "top";
    for (let e = Math.ceil(eLo / d) * d; e <= eHi; e += d) {
      const x = Math.round(xOf(e)) + 0.5;
      g.beginPath(); g.moveTo(x, P.top); g.lineTo(x, P.top + plotH); g.stroke();
      g.fillText(fmtNum(Number(e.toPrecision(12))), x, P.top + plotH + 5);
    }
    g.textAlign = "right"; g.textBaseline = "middle";
    for (let v = Math.ceil(nLo / d) * d; v <= nHi; v += d) {
      const y = Math.round(yOf(v)) + 0.5;
      g.beginPath(); g.moveTo(P.left, y); g.lineTo(P.left + plotW, y); g.stroke();
      g.fillText(fmtNum(Number(v.toPrecision(12))), P.left - 4, y);
    }
    g.textAlign = "left"; g.textBaseline = "bottom";
    g.fillText("E (m) \u2192", P.left + plotW - 60, P.top + plotH - 2);
    g.textBaseline = "top";
    g.fillText("\u2191 N (m)", P.left + 4, P.top + 2);

    // The corrected track wide, the raw INS thin on top of it: over a short
    // run they lie within metres of each other, and the other way round the
    // INS would vanish under the corrected line. Where they part, both show.
    g.save();
    g.beginPath(); g.rect(P.left, P.top, plotW, plotH); g.clip();
    let drawn = 0;
    for (const [E, N, color, width] of lines) {
      g.strokeStyle = color; g.lineWidth = width; g.lineJoin = "round";
      g.beginPath();
      let lx = xOf(E[0]), ly = yOf(N[0]);
      g.moveTo(lx, ly);
      for (let i = 1; i < n; i++) {
        const x = xOf(E[i]), y = yOf(N[i]);
        if (i < n - 1 && Math.abs(x - lx) < 1 && Math.abs(y - ly) < 1) continue;
        g.lineTo(x, y); lx = x; ly = y; drawn++;
      }
      g.stroke();
      // The last point, ringed, is where the vehicle is now.
      g.fillStyle = color;
      g.beginPath(); g.arc(lx, ly, width > 2 ? 5 : 3, 0, 2 * Math.PI); g.fill();
      g.strokeStyle = "#ffffff"; g.lineWidth = 1.5; g.stroke();
    }
    g.restore();
    g.strokeStyle = COLORS.axis; g.lineWidth = 1;
    g.strokeRect(P.left + 0.5, P.top + 0.5, plotW, plotH);

    // Legend inside the plot, in the corner the track crosses least: a fixed
    // corner would sooner or later sit on the vehicle's latest position.
    const items = tr.mechanized ? [["mechanized solution", TRACK_COLORS.solution]]
      : single ? [["corrected = raw INS", TRACK_COLORS.solution]]
        : [["corrected", TRACK_COLORS.solution], ["raw INS", TRACK_COLORS.ins]];
    g.font = "11px system-ui, sans-serif"; g.textAlign = "left"; g.textBaseline = "middle";
    const lw = single ? 150 : 96, lh = 16 * items.length + 6;
    const corners = [
      [P.left + plotW - lw - 6, P.top + 6], [P.left + 6, P.top + 20],
      [P.left + plotW - lw - 6, P.top + plotH - lh - 20], [P.left + 6, P.top + plotH - lh - 6],
    ];
    let lx0 = corners[0][0], ly0 = corners[0][1], fewest = Infinity;
    const stride = Math.max(1, Math.floor(n / 2000)); // a sample is enough to rank four boxes
    for (const [x0, y0] of corners) {
      const inside = (i) => {
        const x = xOf(tr.sE[i]), y = yOf(tr.sN[i]);
        return x >= x0 - 8 && x <= x0 + lw + 8 && y >= y0 - 8 && y <= y0 + lh + 8;
      };
      let hits = inside(n - 1) ? n : 0; // never over the latest position
      for (let i = 0; i < n; i += stride) if (inside(i)) hits++;
      if (hits < fewest) { fewest = hits; lx0 = x0; ly0 = y0; }
      if (hits === 0) break;
    }
    g.fillStyle = "rgba(255, 255, 255, 0.9)"; g.fillRect(lx0, ly0, lw, lh);
    g.strokeStyle = COLORS.grid; g.strokeRect(lx0 + 0.5, ly0 + 0.5, lw, lh);
    items.forEach(([label, color], k) => {
      const y = ly0 + 11 + 16 * k;
      g.strokeStyle = color; g.lineWidth = k === 0 ? 4 : 1.5;
      g.beginPath(); g.moveTo(lx0 + 6, y); g.lineTo(lx0 + 24, y); g.stroke();
      g.fillStyle = COLORS.axis; g.fillText(label, lx0 + 30, y);
    });

    // For tests and the curious: points held, segments drawn, the last offset.
    c.dataset.points = String(n);
    c.dataset.drawn = String(drawn);
    c.dataset.lines = String(lines.length);
    c.dataset.legend = items.map((x) => x[0]).join(", ");
    c.dataset.lastE = String(tr.sE[n - 1]);
    c.dataset.lastN = String(tr.sN[n - 1]);
    return true;
  }
}
