/* Jobs page: all runs with live status (SSE for a few running jobs, polling for the rest), and batches. */
"use strict";
(() => {
  const { api, el, showError, metres, seconds, when, jobDuration, TERMINAL, statusBadge, shortId, progressCell, followJob } = VTD;
  const $ = (id) => document.getElementById(id);
  const MAX_STREAMS = 3; // browsers allow ~6 connections per host: leave room for the page's own requests
  const names = new Map();
  const streams = new Map();
  let timer = null;

  async function sequenceNames() {
    try { for (const s of (await api("/sequences?limit=1000")).items) names.set(s.id, s.name); } catch (_) { /* ids then */ }
  }

  function actions(job) {
    const act = (label, path, method = "POST") => el("button", { type: "button", class: "small", onclick: async () => {
      try { await api(`/jobs/${job.id}${path}`, { method }); refresh(); } catch (err) { showError($("jobs-error"), err, label + " failed"); }
    } }, label);
    if (!TERMINAL.has(job.status)) return act("Cancel", "/cancel");
    if (job.status !== "succeeded") return act("Retry", "/retry");
    return null;
  }

  function row(job) {
    const ate = job.metrics && job.metrics.ate ? job.metrics.ate.rmse : null;
    const err = job.status === "failed" && job.error ? el("div", { class: "small st-failed" }, job.error) : null;
    const act = actions(job); // in the first cell: on screen however far a narrow table scrolls
    return el("tr", { id: "job-" + job.id },
      el("td", {}, el("a", { href: "/jobs/" + job.id }, shortId(job.id)), act ? el("div", { class: "row-actions" }, act) : null),
      el("td", {}, names.get(job.sequence_id) || job.sequence_id.slice(0, 8)),
      el("td", { class: "nw" }, job.preset),
      el("td", {}, statusBadge(job.status), err),
      el("td", {}, progressCell(job)),
      el("td", { class: "n" }, seconds(jobDuration(job))),
      el("td", { class: "n", title: "absolute trajectory error, root mean square" }, metres(ate)),
      el("td", { class: "small nw" }, when(job.created_at)));
  }

  function update(job) {
    const tr = $("job-" + job.id);
    if (tr) tr.replaceWith(row(job));
    if (TERMINAL.has(job.status)) { // the list's counts and the next job to follow change: refresh soon
      if (streams.has(job.id)) { streams.get(job.id)(); streams.delete(job.id); }
      clearTimeout(timer);
      timer = setTimeout(refresh, 300);
    }
  }

  async function refresh() {
    clearTimeout(timer);
    const status = $("status-filter").value;
    try {
      const page = await api("/jobs?limit=100" + (status ? "&status=" + status : ""));
      if (page.items.some((j) => !names.has(j.sequence_id))) await sequenceNames();
      $("jobs-body").replaceChildren(...(page.items.length ? page.items.map(row)
        : [el("tr", {}, el("td", { colspan: 8, class: "muted" }, "No jobs yet: start one from a sequence."))]));
      showError($("jobs-error"), null);
      const active = page.items.filter((j) => !TERMINAL.has(j.status));
      for (const [id, stop] of streams) if (!active.some((j) => j.id === id)) { stop(); streams.delete(id); }
      const live = active.filter((j) => j.status === "running").slice(0, MAX_STREAMS);
      for (const j of live) if (!streams.has(j.id)) streams.set(j.id, followJob(j.id, update));
      const polled = active.length > live.length;
      $("live-note").textContent = active.length
        ? `${active.length} job(s) not finished: ${live.length} followed live, the list refreshes every ${polled ? 2 : 10} s.` : "";
      timer = setTimeout(refresh, polled ? 2000 : 10000);
    } catch (err) {
      showError($("jobs-error"), err, "Could not list the jobs");
      timer = setTimeout(refresh, 5000);
    }
  }

  async function batches() {
    try {
      const page = await api("/batches?limit=50");
      $("batches-body").replaceChildren(...(page.items.length ? page.items.map((b) => el("tr", {},
        el("td", {}, el("a", { href: "/batches/" + b.id }, shortId(b.id))),
        el("td", {}, b.name || "—"),
        el("td", {}, statusBadge(b.status)),
        el("td", { class: "n" }, Object.entries(b.counts).map(([k, v]) => `${v} ${k}`).join(", ") || "0"),
        el("td", {}, b.presets.join(", ")),
        el("td", { class: "small" }, when(b.created_at))))
        : [el("tr", {}, el("td", { colspan: 6, class: "muted" }, "No batches yet: tick sequences and presets on the Sequences page."))]));
    } catch (err) { $("batches-body").replaceChildren(el("tr", {}, el("td", { colspan: 6, class: "error" }, err.message))); }
  }

  $("status-filter").addEventListener("change", refresh);
  sequenceNames().then(refresh);
  batches();
})();
