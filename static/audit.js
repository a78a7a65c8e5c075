// audit.js — the audit log (GET /api/v1/audit): who changed what through the API,
// when, from where and why, newest first, filtered by session and actor, a page at a
// time with the server's `next_before` cursor. The values before and after a change
// are folded away under a disclosure, as JSON.

import { el, fmtClock } from "./dom.js";
import { get, HttpError } from "./api.js";

const PAGE = 50;

/** A value as indented JSON, or "—" for null. */
function json(v) {
  return v === null || v === undefined ? "\u2014" : JSON.stringify(v, null, 2);
}

export class AuditView {
  constructor(root) {
    this.tbody = root.querySelector("#audit");
    this.empty = root.querySelector("#no-audit");
    this.form = root.querySelector("#audit-filters");
    this.pageText = root.querySelector("#audit-page");
    this.newerBtn = root.querySelector("#audit-newer");
    this.olderBtn = root.querySelector("#audit-older");
    this.cursors = [null]; // `before` of each page visited; [0] = newest
    this.next = null;
    this.filters = {};
    this.form.addEventListener("submit", (ev) => { ev.preventDefault(); this.readFilters(); this.cursors = [null]; this.load(); });
    this.olderBtn.addEventListener("click", () => { if (this.next !== null) { this.cursors.push(this.next); this.load(); } });
    this.newerBtn.addEventListener("click", () => { if (this.cursors.length > 1) { this.cursors.pop(); this.load(); } });
  }

  open() { this.readFilters(); this.load(); }
  render() {}

  readFilters() {
    const f = new FormData(this.form);
    this.filters = {
      session: String(f.get("session") || "").trim() || null,
      actor: String(f.get("actor") || "").trim() || null,
    };
  }

  async load() {
    const q = new URLSearchParams({ limit: String(PAGE) });
    for (const k of ["session", "actor"]) if (this.filters[k] !== null) q.set(k, this.filters[k]);
    const before = this.cursors[this.cursors.length - 1];
    if (before !== null) q.set("before", String(before));
    this.pageText.textContent = "Loading\u2026";
    try {
      const page = await get("api/v1/audit?" + q);
      this.next = page.next_before;
      this.tbody.replaceChildren(...page.entries.map((e) => this.row(e)));
      this.empty.hidden = page.entries.length > 0;
      this.pageText.textContent = "Page " + this.cursors.length + (page.entries.length ? "" : " (empty)");
    } catch (e) {
      this.tbody.replaceChildren();
      this.next = null;
      this.pageText.textContent = e instanceof HttpError && e.status === 404
        ? "This server has no audit log."
        : "Could not load the audit log: " + e.message;
    }
    this.newerBtn.disabled = this.cursors.length <= 1;
    this.olderBtn.disabled = this.next === null;
  }

  row(e) {
    const values = el("details", { class: "audit-values" },
      el("summary", null, "show"),
      el("div", { class: "muted" }, "previous"), el("pre", null, json(e.previous)),
      el("div", { class: "muted" }, "new"), el("pre", null, json(e.new)));
    const client = e.client || "\u2014";
    return el("tr", { "data-audit-id": e.id, "data-actor": e.actor },
      el("td", null, el("time", { datetime: new Date(e.at_ms).toISOString() }, fmtClock(e.at_ms))),
      el("td", { class: "wrap" }, e.actor),
      el("td", { class: "wrap" }, el("code", null, e.method + " " + e.route), el("div", { class: "muted small" }, e.path)),
      el("td", { class: "wrap" }, e.session ? el("a", { href: "#/session/" + encodeURIComponent(e.session) }, e.session) : "\u2014"),
      el("td", { class: "wrap" }, e.reason || "\u2014"),
      el("td", { class: "wrap", title: e.forwarded_for ? "X-Forwarded-For: " + e.forwarded_for : "" },
        client + (e.forwarded_for ? " (for " + e.forwarded_for + ")" : "")),
      el("td", null, values));
  }
}
