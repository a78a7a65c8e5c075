// controls.js — edit one monitor's threshold, policy and alarm level, and
// per-test thresholds. The operator states either a false-alarm probability
// or a raw threshold; while they type, the threshold each test would get is
// previewed from /api/v1/chi2/threshold for that test's dof (a test with a
// threshold of its own keeps it). "Apply" sends the REST PUT, and the panel
// shows what the server answered (the thresholds now in force), not what was
// typed. An optional reason goes with the change to the audit log
// (`X-Navguard-Reason`).

import { el, fmtNum, policyLevelText, isNum } from "./dom.js";
import { get, request } from "./api.js";

export class ThresholdControls {
  constructor(sessionId, monitor, onApplied) {
    this.path = "api/v1/sessions/" + encodeURIComponent(sessionId) + "/monitors/" + encodeURIComponent(monitor) + "/threshold";
    this.onApplied = onApplied;
    this.view = null;
    this.previewSeq = 0;
    const id = (s) => "ctl-" + sessionId + "-" + monitor + "-" + s;
    this.mode = el("select", { id: id("mode"), name: "mode", "data-control": "mode" },
      el("option", { value: "p_fa" }, "false-alarm probability p_fa"),
      el("option", { value: "threshold" }, "raw threshold"));
    this.value = el("input", { id: id("value"), name: "value", type: "number", step: "any", min: "0", required: true, "data-control": "value" });
    this.policy = el("select", { id: id("policy"), name: "policy", "data-control": "policy" },
      el("option", { value: "classic" }, "classic"), el("option", { value: "counters" }, "counters (seed 004)"),
      el("option", { value: "traditional" }, "traditional (seed 004: update, leave out of fusion)"));
    this.level = el("select", { id: id("level"), name: "alarm_level", "data-control": "alarm-level" },
      el("option", { value: "isolated" }, "isolated (suspect is a warning)"), el("option", { value: "suspect" }, "suspect"));
    this.own = el("div", { class: "own-thresholds" });
    this.ownInputs = new Map();
    this.n1 = el("input", { id: id("n1"), type: "number", min: "1", step: "1", value: "10", "data-control": "n1" });
    this.n2 = el("input", { id: id("n2"), type: "number", min: "0", step: "1", value: "5", "data-control": "n2" });
    this.counters = el("span", { class: "counters" },
      el("label", { for: id("n1") }, "N1"), this.n1, el("label", { for: id("n2") }, "N2"), this.n2);
    this.preview = el("ul", { class: "preview", "aria-live": "polite" });
    this.applied = el("p", { class: "applied", "aria-live": "polite", "data-control": "applied" });
    this.reason = el("input", { id: id("reason"), name: "reason", type: "text", maxlength: "500", size: "40", "data-control": "reason",
      placeholder: "optional: kept in the audit log" });
    this.apply = el("button", { type: "submit", "data-control": "apply" }, "Apply");
    this.form = el("form", { class: "controls" },
      el("div", { class: "row" },
        el("label", { for: id("mode") }, "Set by"), this.mode,
        el("label", { for: id("value") }, "value"), this.value),
      el("div", { class: "row" },
        el("label", { for: id("policy") }, "Policy"), this.policy, this.counters,
        el("label", { for: id("level") }, "Alarm on"), this.level, this.apply),
      el("div", { class: "row" }, el("label", { for: id("reason") }, "Reason"), this.reason),
      el("div", { class: "row" }, el("span", { class: "muted" }, "Preview:"), this.preview),
      el("details", null, el("summary", null, "Per-test thresholds (e.g. from navguard calibrate)"), this.own),
      this.applied);
    this.idPrefix = id("test");
    this.el = this.form;
    this.form.addEventListener("submit", (ev) => { ev.preventDefault(); this.submit(); });
    for (const input of [this.mode, this.value]) input.addEventListener("input", () => this.schedulePreview());
    this.policy.addEventListener("change", () => { this.counters.hidden = this.policy.value !== "counters"; });
    this.load();
  }

  async load() {
    try {
      this.show(await get(this.path), false);
    } catch (e) {
      this.applied.textContent = "Could not read the threshold: " + e.message;
    }
  }

  /** Fills the form from a ThresholdView (GET or PUT answer). */
  show(view, applied) {
    this.view = view;
    const byP = isNum(view.p_fa);
    this.mode.value = byP ? "p_fa" : "threshold";
    this.value.value = String(byP ? view.p_fa : view.threshold);
    const p = view.policy || { kind: "classic" };
    this.policy.value = ["counters", "traditional"].includes(p.kind) ? p.kind : "classic";
    if (p.kind === "counters") { this.n1.value = String(p.n1); this.n2.value = String(p.n2); }
    this.counters.hidden = this.policy.value !== "counters";
    this.level.value = view.alarm_level === "suspect" ? "suspect" : "isolated";
    this.fillOwn(view);
    const tests = Object.entries(view.tests || {})
      .map(([t, v]) => t + " " + fmtNum(v.threshold) + (v.own ? " own" : "") + " (dof " + v.dof + ")").join(", ");
    this.applied.textContent = (applied ? "Applied: " : "In force: ") +
      (byP ? "p_fa " + view.p_fa : "threshold " + fmtNum(view.threshold)) + ", " + policyLevelText(p, view.alarm_level) +
      (tests ? " \u2014 " + tests : "");
    this.applied.dataset.state = applied ? "applied" : "loaded";
    this.renderPreview();
  }

  /** One raw-threshold field per test: filled when the test has its own, blank when it follows the monitor. */
  fillOwn(view) {
    this.ownInputs = new Map();
    const rows = Object.entries(view.tests || {}).map(([name, t]) => {
      const input = el("input", { id: this.idPrefix + "-" + name, type: "number", step: "any", min: "0",
        placeholder: "monitor's", "data-control": "own", "data-test": name });
      if (t.own) input.value = String(t.threshold);
      this.ownInputs.set(name, { input, own: t.own });
      return el("div", { class: "row" }, el("label", { for: input.id }, name + " (dof " + t.dof + ")"), input);
    });
    this.own.replaceChildren(...rows);
  }

  schedulePreview() {
    clearTimeout(this.previewTimer);
    this.previewTimer = setTimeout(() => this.renderPreview(), 200);
  }

  /** One line per test: the threshold the typed value would give it. */
  async renderPreview() {
    const seq = ++this.previewSeq;
    const tests = Object.entries((this.view && this.view.tests) || {});
    const v = Number(this.value.value);
    const lines = [];
    for (const [name, t] of tests) {
      if (t.own) { lines.push(name + ": own " + fmtNum(t.threshold)); continue; }
      if (this.mode.value === "threshold") { lines.push(name + ": " + (isNum(v) && v > 0 ? fmtNum(v) : "?")); continue; }
      if (!(v > 0 && v < 1)) { lines.push(name + ": p_fa must be in (0, 1)"); continue; }
      try {
        const a = await get("api/v1/chi2/threshold?dof=" + t.dof + "&p_fa=" + encodeURIComponent(v));
        lines.push(name + " (dof " + t.dof + "): " + fmtNum(a.threshold));
      } catch (e) {
        lines.push(name + ": " + e.message);
      }
    }
    if (seq !== this.previewSeq) return; // a newer keystroke won
    this.preview.replaceChildren(...lines.map((l) => el("li", { "data-preview": "" }, l)));
  }

  async submit() {
    const v = Number(this.value.value);
    const body = this.mode.value === "p_fa" ? { p_fa: v } : { threshold: v };
    body.policy = this.policy.value === "counters"
      ? { kind: "counters", n1: Number(this.n1.value), n2: Number(this.n2.value) }
      : { kind: this.policy.value };
    body.alarm_level = this.level.value;
    const tests = {};
    for (const [name, { input, own }] of this.ownInputs) {
      if (input.value !== "") tests[name] = { threshold: Number(input.value) };
      else if (own) tests[name] = null;
    }
    if (Object.keys(tests).length) body.tests = tests;
    const reason = this.reason.value.trim();
    // A header carries ISO-8859-1 from a browser; fetch refuses anything beyond it.
    if (/[^\u0000-\u00ff]/.test(reason)) {
      this.applied.textContent = "The reason may hold Latin-1 characters only (letters like \u00e9 are fine).";
      this.applied.dataset.state = "error";
      return;
    }
    this.apply.disabled = true;
    this.applied.textContent = "Applying\u2026";
    try {
      const view = await request("PUT", this.path, body, reason ? { "X-Navguard-Reason": reason } : undefined);
      this.reason.value = "";
      this.show(view, true);
      if (this.onApplied) this.onApplied(view);
    } catch (e) {
      this.applied.textContent = "Refused: " + e.message;
      this.applied.dataset.state = "error";
    } finally {
      this.apply.disabled = false;
    }
  }
}
