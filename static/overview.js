// overview.js — every session at a glance: its monitors and tests as state
// badges, the worst test ratio, epochs per second and the age of the last
// frame. Cards are built once per session shape and then only their text and
// data-state attributes change, so 20 updates a second stay cheap.

import { el, setText, badge, setBadge, fmtRatio, fmtAge, fmtNum, worstState, policyText, isNum, DASH } from "./dom.js";

export class OverviewView {
  constructor(live, root) {
    this.live = live;
    this.root = root;
    this.list = root.querySelector("#sessions");
    this.empty = root.querySelector("#no-sessions");
    this.cards = new Map(); // id → card
    this.dirty = true;
    live.on("sessions", () => { this.dirty = true; });
    live.on("stats", () => { this.dirty = true; });
    live.on("state", () => { this.dirty = true; });
  }

  render() {
    if (!this.dirty) return;
    this.dirty = false;
    const live = this.live;
    let prev = null;
    for (const s of live.sessions.values()) {
      let card = this.cards.get(s.id);
      if (!card) { card = this.makeCard(s.id); this.cards.set(s.id, card); }
      this.fill(card, s);
      const want = prev ? prev.nextSibling : this.list.firstChild;
      if (want !== card.el) this.list.insertBefore(card.el, want);
      prev = card.el;
    }
    for (const [id, card] of this.cards) if (!live.sessions.has(id)) { card.el.remove(); this.cards.delete(id); }
    if (live.loaded) this.empty.textContent = "No sessions yet. Create one with POST /api/v1/sessions or `navguard replay`.";
    this.empty.hidden = live.sessions.size > 0;
  }

  /** Age and rate change with the clock, not only with messages. */
  tick() { this.dirty = true; }

  makeCard(id) {
    const f = {
      conn: el("dd", { "data-field": "stream" }), worst: el("dd", { class: "num", "data-field": "worst" }),
      eps: el("dd", { class: "num", "data-field": "rate" }), age: el("dd", { class: "num", "data-field": "age" }),
      epochs: el("dd", { class: "num", "data-field": "epochs" }), live: el("dd", { "data-field": "events" }),
    };
    const fact = (label, dd) => el("div", null, el("dt", null, label), dd);
    const tbody = el("tbody");
    const link = el("a", { href: "#/session/" + encodeURIComponent(id) }, id);
    const article = el("article", { class: "session card", "data-session": id },
      el("div", { class: "session-head" },
        el("h3", null, el("span", { class: "sr" }, "Session "), link),
        el("dl", { class: "facts" },
          fact("Stream", f.conn), fact("Worst test ratio", f.worst), fact("Epochs/s", f.eps),
          fact("Last frame", f.age), fact("Epochs", f.epochs), fact("Events", f.live))),
      el("table", { class: "monitors" },
        el("thead", null, el("tr", null,
          el("th", { scope: "col" }, "Monitor"), el("th", { scope: "col" }, "Type \u00b7 policy"),
          el("th", { scope: "col" }, "State"), el("th", { scope: "col", class: "num" }, "Worst ratio"),
          el("th", { scope: "col" }, "Tests (state, since t, last ratio)"))),
        tbody));
    return { el: article, f, tbody, shape: "", rows: new Map() };
  }

  fill(card, s) {
    const monitors = s.monitors();
    // Rebuild the rows only when the set of monitors/tests or their policy changed.
    const shape = JSON.stringify(monitors.map((m) => [m.name, m.type, Object.keys(m.tests),
      m.spec && [policyText(m.spec.policy), m.spec.p_fa, m.spec.threshold]]));
    if (shape !== card.shape) {
      card.shape = shape;
      card.rows = new Map();
      const rows = monitors.map((m) => {
        const mb = badge(null, { "data-kind": "monitor", "data-monitor": m.name });
        const avail = el("span", { class: "availability", "data-kind": "availability", "data-monitor": m.name, hidden: true });
        const worst = el("td", { class: "num" }, DASH);
        const list = el("ul", { class: "tests" });
        const tests = new Map();
        for (const t of Object.keys(m.tests)) {
          const tb = badge(null, { "data-kind": "test", "data-monitor": m.name, "data-test": t }, t);
          const since = el("span", { class: "num muted since" });
          const ratio = el("span", { class: "num ratio" }, DASH);
          const cons = el("span", { class: "consistency", "data-kind": "consistency", "data-monitor": m.name, "data-test": t });
          list.append(el("li", null, tb, since, ratio, cons));
          tests.set(t, { badge: tb, since, ratio, cons });
        }
        let config = m.type || "";
        if (m.spec) {
          const extra = [policyText(m.spec.policy)];
          if (isNum(m.spec.p_fa)) extra.push("p_fa " + m.spec.p_fa);
          if (isNum(m.spec.threshold)) extra.push("threshold " + fmtNum(m.spec.threshold));
          config = [config, ...extra.filter(Boolean)].join(" \u00b7 ");
        }
        card.rows.set(m.name, { badge: mb, avail, worst, tests });
        return el("tr", null, el("th", { scope: "row" }, m.name), el("td", null, config), el("td", null, mb, " ", avail), worst, el("td", null, list));
      });
      card.tbody.replaceChildren(...rows);
    }
    const all = [];
    let sessionWorst = null;
    for (const m of monitors) {
      const row = card.rows.get(m.name);
      if (!row) continue;
      const states = [];
      for (const [t, ts] of Object.entries(m.tests)) {
        const cell = row.tests.get(t);
        if (!cell) continue;
        setBadge(cell.badge, ts.state);
        states.push(ts.state);
        setText(cell.since, isNum(ts.state_since_t) && ts.state !== "healthy" ? "since t " + fmtNum(ts.state_since_t) + " s" : "");
        setText(cell.ratio, fmtRatio(ts.last_test_ratio));
        cell.ratio.classList.toggle("over", ts.last_test_ratio > 1);
        // Only a model that is not ok is worth the space here; the session view has the figures.
        const flag = ts.consistency && ts.consistency.flag;
        const bad = flag && flag !== "ok" ? flag : "";
        setText(cell.cons, bad);
        if (cell.cons.dataset.flag !== bad) cell.cons.dataset.flag = bad;
        const title = t + ": " + (ts.state || "unknown") + (isNum(ts.dof) ? ", dof " + ts.dof : "") +
          (isNum(ts.threshold) ? ", threshold " + fmtNum(ts.threshold) : "") + (isNum(ts.last) ? ", last " + fmtNum(ts.last) : "");
        if (cell.badge.title !== title) cell.badge.title = title;
      }
      const w = worstState(states);
      setBadge(row.badge, w);
      const integrity = m.live && m.live.integrity;
      row.avail.hidden = !integrity;
      if (integrity) {
        setText(row.avail, integrity.state);
        if (row.avail.dataset.state !== integrity.state) row.avail.dataset.state = integrity.state;
      }
      if (w) all.push(w);
      const wr = m.live ? m.live.worst_test_ratio : null;
      setText(row.worst, fmtRatio(wr));
      row.worst.classList.toggle("over", wr > 1);
      if (isNum(wr) && (sessionWorst === null || wr > sessionWorst)) sessionWorst = wr;
    }
    const worst = worstState(all);
    card.el.dataset.state = worst || "unknown";
    const st = s.stats;
    const connected = st ? st.connected : !!(s.info && s.info.connected);
    setText(card.f.conn, connected ? "connected" : "not connected");
    card.f.conn.classList.toggle("flag-off", !connected);
    setText(card.f.worst, fmtRatio(sessionWorst));
    card.f.worst.classList.toggle("over", sessionWorst > 1);
    setText(card.f.epochs, st && isNum(st.epochs) ? String(st.epochs) : DASH);
    // Age from the server's own clock (published_at_ms), so a skewed client clock does not lie.
    const age = st && isNum(st.last_frame_at_ms)
      ? st.published_at_ms - st.last_frame_at_ms + (Date.now() - s.statsAt) : null;
    setText(card.f.age, fmtAge(age));
    const eps = st && isNum(st.epochs_per_s) ? st.epochs_per_s : 0;
    // The rate is recomputed only when a frame arrives, so call it idle once frames are overdue.
    const idle = !st || !connected || age === null || age > 3000;
    setText(card.f.eps, st ? (idle ? "0 (idle)" : eps.toFixed(eps >= 100 ? 0 : 1)) : DASH);
    const liveText = s.liveText();
    setText(card.f.live, liveText);
    card.f.live.classList.toggle("flag-off", liveText !== "live");
    const liveState = liveText.split(" ")[0].replace("\u2026", "");
    if (card.el.dataset.live !== liveState) card.el.dataset.live = liveState;
  }
}
