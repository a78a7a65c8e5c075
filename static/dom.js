// dom.js — small DOM and number-formatting helpers shared by every view.
// Text always goes in as text nodes (never innerHTML), so names a client
// chose for sessions or monitors cannot inject markup.

/** Builds an element; `attrs` values of null/undefined/false are skipped. */
export function el(tag, attrs, ...kids) {
  const e = document.createElement(tag);
  if (attrs) {
    for (const [k, v] of Object.entries(attrs)) {
      if (v === null || v === undefined || v === false) continue;
      if (k === "class") e.className = v;
      else if (k.startsWith("on") && typeof v === "function") e.addEventListener(k.slice(2), v);
      else e.setAttribute(k, v === true ? "" : String(v));
    }
  }
  for (const k of kids.flat()) if (k !== null && k !== undefined && k !== false) e.append(k);
  return e;
}

/** Sets text only when it changed: avoids layout work at 20 updates a second. */
export function setText(node, text) {
  if (node.textContent !== text) node.textContent = text;
}

export const isNum = (x) => typeof x === "number" && Number.isFinite(x);

export const DASH = "\u2014";

/** Four significant digits, exponent outside [1e-3, 1e5). */
export function fmtNum(x) {
  if (!isNum(x)) return DASH;
  const a = Math.abs(x);
  if (a !== 0 && (a >= 1e5 || a < 1e-3)) return x.toExponential(2);
  return String(Number(x.toPrecision(4)));
}

/** A test ratio: two decimals, exponent when huge (a fault can give 1e6). */
export function fmtRatio(x) {
  if (!isNum(x)) return DASH;
  return Math.abs(x) >= 1000 ? x.toExponential(2) : x.toFixed(2);
}

/** Epoch time in seconds: to the millisecond, or to the tenth for times of 1e6 s and more. */
export function fmtT(x) {
  if (!isNum(x)) return DASH;
  // Large times (GNSS sessions stream GPS seconds, ~1.4e9) keep every whole second, so
  // neighbouring ticks and epochs stay distinct.
  return Math.abs(x) >= 1e6 ? String(Number(x.toFixed(1))) : String(Number(x.toFixed(3)));
}

export function fmtAge(ms) {
  if (!isNum(ms)) return "never";
  const s = Math.max(0, ms) / 1000;
  if (s < 10) return s.toFixed(1) + " s ago";
  if (s < 120) return Math.round(s) + " s ago";
  if (s < 7200) return Math.round(s / 60) + " min ago";
  if (s < 172800) return Math.round(s / 3600) + " h ago";
  return Math.round(s / 86400) + " d ago";
}

/** Wall-clock time: time of day today, date and time otherwise. */
export function fmtClock(ms) {
  if (!isNum(ms)) return DASH;
  const d = new Date(ms);
  const time = d.toLocaleTimeString(undefined, { hour: "2-digit", minute: "2-digit", second: "2-digit", hour12: false });
  if (d.toDateString() === new Date().toDateString()) return time;
  return d.toLocaleDateString(undefined, { year: "numeric", month: "2-digit", day: "2-digit" }) + " " + time;
}

export const STATES = ["healthy", "suspect", "isolated"];
const GLYPH = { healthy: "\u2713", suspect: "!", isolated: "\u2715", unknown: "?" };

export function stateRank(s) { return STATES.indexOf(s); }

/** The worst of a list of states, or null for an empty list. */
export function worstState(list) {
  let worst = null;
  for (const s of list) if (s && (worst === null || stateRank(s) > stateRank(worst))) worst = s;
  return worst;
}

/**
 * A state badge: colour, glyph and word, so the state does not rest on
 * colour alone. `attrs` carries the data-* attributes the tests look for.
 */
export function badge(state, attrs, label) {
  const glyph = el("span", { "aria-hidden": "true" });
  const word = el("span", { class: "word" });
  const b = el("span", Object.assign({ class: "badge" }, attrs || {}),
    label ? el("span", { class: "name" }, label) : null, glyph, word);
  b.glyph = glyph;
  b.word = word;
  setBadge(b, state);
  return b;
}

export function setBadge(b, state) {
  const s = STATES.includes(state) ? state : "unknown";
  if (b.dataset.state === s) return;
  b.dataset.state = s;
  setText(b.glyph, GLYPH[s]);
  setText(b.word, s);
}

/** `{kind: "counters", n1, n2}` → "counters (N1 10, N2 5)". */
export function policyText(p) {
  if (!p || typeof p !== "object") return "";
  if (p.kind === "counters") return "counters (N1 " + p.n1 + ", N2 " + p.n2 + ")";
  return String(p.kind ?? "");
}

/** An alarm-log entry's severity as a tag: "alarm" (red) or "warning" (amber). */
export function severityTag(severity) {
  const s = severity === "warning" ? "warning" : "alarm";
  return el("span", { class: "severity", "data-severity": s }, s);
}

/** A test's consistency summary as one line: "NIS 1.02 × dof · ρ₁ 0.04 · ok". */
export function consistencyText(c) {
  if (!c || !isNum(c.nis_mean)) return "";
  const parts = ["NIS " + fmtNum(c.nis_mean / c.dof) + "\u00d7dof"];
  if (isNum(c.autocorr)) parts.push("\u03c1\u2081 " + c.autocorr.toFixed(2));
  parts.push(c.flag || "(" + c.samples + " epochs)");
  return parts.join(" \u00b7 ");
}

/** `{kind: "counters", n1, n2}` → "counters (N1 10, N2 5)"; the alarm level when not the default. */
export function policyLevelText(p, level) {
  const text = policyText(p);
  return level === "suspect" ? text + ", alarm on suspect" : text;
}
