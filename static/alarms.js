// alarms.js — the persisted alarm log (GET /api/v1/alarms), newest first,
// filtered by session, monitor, severity and raise time, a page at a time with the
// server's `next_before` cursor. On the first page an alarm arriving live on
// any events socket is inserted at the top when it passes the filters.
// Unacknowledged entries are highlighted; a token with `operate` may acknowledge one
// with a comment (POST …/alarms/{id}/ack), which the row then shows.

import { el, badge, fmtNum, fmtRatio, fmtT, fmtClock, severityTag } from "./dom.js";
import { get, request } from "./api.js";

/** Longest acknowledgement comment the server takes, characters. */
const MAX_COMMENT = 500;

const PAGE = 25;

export class AlarmsView {
  constructor(live, root) {
    this.live = live;
    this.tbody = root.querySelector("#alarms");
    this.empty = root.querySelector("#no-alarms");
    this.form = root.querySelector("#alarm-filters");
    this.pageText = root.querySelector("#alarm-page");
    this.newerBtn = root.querySelector("#alarms-newer");
    this.olderBtn = root.querySelector("#alarms-older");
    this.sessionList = root.querySelector("#alarm-session-list");
    this.cursors = [null]; // `before` of each page visited; [0] = newest
    this.next = null;
    this.filters = {};
    this.shown = new Set();
    this.form.addEventListener("submit", (ev) => { ev.preventDefault(); this.readFilters(); this.cursors = [null]; this.load(); });
    this.olderBtn.addEventListener("click", () => { if (this.next !== null) { this.cursors.push(this.next); this.load(); } });
    this.newerBtn.addEventListener("click", () => { if (this.cursors.length > 1) { this.cursors.pop(); this.load(); } });
    live.on("alarm", (a, isLive) => { if (isLive) this.onLive(a); });
    live.on("sessions", () => this.fillSessionList());
  }

  open() { this.readFilters(); this.load(); }
  render() {}

  readFilters() {
    const f = new FormData(this.form);
    const ms = (v) => (v ? new Date(String(v)).getTime() : null);
    this.filters = {
      session: String(f.get("session") || "").trim() || null,
      monitor: String(f.get("monitor") || "").trim() || null,
      severity: String(f.get("severity") || "") || null,
      since: ms(f.get("since")),
      until: ms(f.get("until")),
    };
  }

  fillSessionList() {
    const ids = [...this.live.sessions.keys()];
    if (this.sessionList.childElementCount === ids.length) return;
    this.sessionList.replaceChildren(...ids.map((id) => el("option", { value: id })));
  }

  matches(a) {
    const f = this.filters;
    return (!f.session || a.session === f.session) && (!f.monitor || a.monitor === f.monitor) &&
      (!f.severity || (a.severity || "alarm") === f.severity) &&
      (f.since === null || a.raised_at_ms >= f.since) && (f.until === null || a.raised_at_ms < f.until);
  }

  async load() {
    const q = new URLSearchParams({ limit: String(PAGE) });
    for (const k of ["session", "monitor", "severity", "since", "until"]) if (this.filters[k] !== null) q.set(k, String(this.filters[k]));
    const before = this.cursors[this.cursors.length - 1];
    if (before !== null) q.set("before", String(before));
    this.pageText.textContent = "Loading\u2026";
    try {
      const page = await get("api/v1/alarms?" + q);
      this.next = page.next_before;
      this.shown = new Set();
      this.tbody.replaceChildren(...page.alarms.map((a) => this.row(a, false)));
      this.empty.hidden = page.alarms.length > 0;
      this.pageText.textContent = "Page " + this.cursors.length + (page.alarms.length ? "" : " (empty)");
    } catch (e) {
      this.pageText.textContent = "Could not load the log: " + e.message;
    }
    this.newerBtn.disabled = this.cursors.length <= 1;
    this.olderBtn.disabled = this.next === null;
  }

  onLive(a) {
    // Only the newest page grows; older pages are a stable view of the past.
    if (this.cursors.length !== 1 || !this.matches(a) || this.shown.has(a.id)) return;
    this.tbody.prepend(this.row(a, true));
    this.empty.hidden = true;
    while (this.tbody.childElementCount > PAGE) this.tbody.lastElementChild.remove();
  }

  row(a, fresh) {
    if (a.id > 0) this.shown.add(a.id);
    const cleared = a.cleared_t !== null && a.cleared_t !== undefined;
    const tr = el("tr", { "data-alarm-id": a.id, "data-session": a.session, "data-severity": a.severity || "alarm", class: (cleared ? "cleared" : "") + (fresh ? " fresh" : "") },
      el("td", null, el("time", { datetime: new Date(a.raised_at_ms).toISOString() }, fmtClock(a.raised_at_ms))),
      el("td", null, severityTag(a.severity)),
      el("td", { class: "wrap" }, el("a", { href: "#/session/" + encodeURIComponent(a.session) }, a.session)),
      el("td", { class: "wrap" }, a.monitor), el("td", { class: "wrap" }, a.test),
      el("td", null, badge(a.state)),
      el("td", { class: "num" }, fmtNum(a.statistic) + " / " + fmtNum(a.threshold) + " (dof " + a.dof + ")"),
      el("td", { class: "num" + (a.test_ratio > 1 ? " over" : "") }, fmtRatio(a.test_ratio)),
      el("td", { class: "num" }, fmtT(a.t)),
      el("td", { class: "num" }, fmtT(a.delay_s)),
      el("td", null, cleared ? "at t = " + fmtT(a.cleared_t) : "active"),
      el("td", { class: "wrap" }, this.ackCell(a)));
    if (!a.acked_by) tr.classList.add("unacked");
    if (fresh) setTimeout(() => tr.classList.remove("fresh"), 4000);
    return tr;
  }

  /** Who acknowledged the entry, when and why; or the button that asks for a comment. */
  ackCell(a) {
    if (a.acked_by) {
      return el("span", { "data-acked": "true", title: a.ack_comment || "" },
        "by " + a.acked_by + " at " + fmtClock(a.acked_at_ms) + ": " + (a.ack_comment || ""));
    }
    if (!(a.id > 0)) return el("span", { class: "muted" }, "not stored");
    const msg = el("span", { class: "muted", "aria-live": "polite" });
    const btn = el("button", { type: "button", "data-control": "ack", "data-needs": "operate" }, "Acknowledge");
    btn.addEventListener("click", async () => {
      const comment = (window.prompt("Acknowledge alarm " + a.id + " of " + a.session + ": what was found or done?") || "").trim();
      if (!comment) return;
      if (comment.length > MAX_COMMENT) { msg.textContent = "At most " + MAX_COMMENT + " characters."; return; }
      btn.disabled = true;
      try {
        const acked = await request("POST", "api/v1/sessions/" + encodeURIComponent(a.session) + "/alarms/" + a.id + "/ack", { comment });
        btn.closest("tr").replaceWith(this.row(acked, false));
      } catch (e) {
        // 409: somebody acknowledged it meanwhile; the reload shows who.
        if (e.status === 409) this.load(); else { msg.textContent = e.message; btn.disabled = false; }
      }
    });
    return el("span", null, btn, " ", msg);
  }
}
