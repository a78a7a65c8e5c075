// models.js — stored models and training jobs (GET /api/v1/models): kind,
// parameters, training metrics, a progress bar for jobs still training, and
// delete (which also cancels a running job). Polls faster while a job runs.
// A server without the model API (404) simply shows "no models".

import { el, fmtClock, fmtNum } from "./dom.js";
import { get, request, HttpError } from "./api.js";

const FAST_MS = 1000;
const SLOW_MS = 5000;

/** `{a: 1, b: {c: 2}}` → "a 1 · b.c 2": compact and readable for params and metrics. */
function flat(obj, prefix = "") {
  if (obj === null || obj === undefined) return [];
  if (typeof obj !== "object" || Array.isArray(obj)) {
    const v = typeof obj === "number" ? fmtNum(obj) : Array.isArray(obj) ? "[" + obj.map((x) => (typeof x === "number" ? fmtNum(x) : String(x))).join(", ") + "]" : String(obj);
    return [prefix + " " + v];
  }
  return Object.entries(obj).flatMap(([k, v]) => flat(v, prefix ? prefix + "." + k : k));
}

export class ModelsView {
  constructor(root) {
    this.tbody = root.querySelector("#models");
    this.empty = root.querySelector("#no-models");
    this.timer = null;
    this.active = false;
  }

  open() { this.active = true; this.load(); }
  close() { this.active = false; clearTimeout(this.timer); }
  render() {}

  async load() {
    clearTimeout(this.timer);
    if (!this.active) return;
    let training = false;
    try {
      const data = await get("api/v1/models");
      const models = (data && data.models) || [];
      training = models.some((m) => m.status === "training");
      this.tbody.replaceChildren(...models.map((m) => this.row(m)));
      this.empty.hidden = models.length > 0;
      this.empty.textContent = "No models.";
    } catch (e) {
      this.tbody.replaceChildren();
      this.empty.hidden = false;
      this.empty.textContent = e instanceof HttpError && e.status === 404
        ? "No models (this server has no model API)."
        : "No models: " + e.message;
    }
    if (this.active) this.timer = setTimeout(() => this.load(), training ? FAST_MS : SLOW_MS);
  }

  row(m) {
    let status;
    if (m.status === "training") {
      const frac = Math.max(0, Math.min(1, (m.progress && m.progress.fraction) || 0));
      status = el("div", { class: "progress-cell" },
        el("progress", { max: "1", value: String(frac), "aria-label": "training progress" }),
        el("span", { class: "num" }, Math.round(frac * 100) + " %"),
        el("span", { class: "muted" }, (m.progress && m.progress.stage) || ""));
    } else if (m.status === "failed") {
      status = el("span", { class: "failed" }, "failed: " + (m.error || "unknown reason"));
    } else {
      status = el("span", null, m.status);
    }
    const del = el("button", { type: "button", "data-model": m.id, "data-needs": "admin" }, m.status === "training" ? "Cancel" : "Delete");
    del.addEventListener("click", async () => {
      del.disabled = true;
      try { await request("DELETE", "api/v1/models/" + encodeURIComponent(m.id)); } catch (_) { /* reload shows the truth */ }
      this.load();
    });
    return el("tr", { "data-model": m.id, "data-status": m.status },
      el("td", null, el("code", null, m.id), m.name ? el("div", { class: "muted" }, m.name) : null),
      el("td", null, m.kind),
      el("td", null, status),
      el("td", { class: "small" }, flat(m.params).join(" \u00b7 ")),
      el("td", { class: "num" }, m.n + " \u00d7 " + m.dim),
      el("td", { class: "small" }, flat(m.metrics).join(" \u00b7 ")),
      el("td", null, fmtClock(m.created_ms)),
      el("td", null, del));
  }
}
