/* The first page's runs: what is running or waiting now, and what just finished, each linked to its page. */
"use strict";
(() => {
  const { api, el, showError, metres, seconds, when, jobDuration, TERMINAL, statusBadge, isNum, etaText } = VTD;
  const $ = (id) => document.getElementById(id);
  const RECENT = 5;
  const names = new Map();
  let timer = null;

  async function sequenceNames(jobs) {
    if (jobs.every((j) => names.has(j.sequence_id))) return;
    try { for (const s of (await api("/sequences?limit=200")).items) names.set(s.id, s.name); } catch (_) { /* ids then */ }
  }
  const seqName = (job) => names.get(job.sequence_id) || job.sequence_id.slice(0, 8);

  function activeItem(job) {
    const pct = Math.round(100 * (job.progress || 0));
    const state = job.status === "queued" ? "waiting for a worker"
      : `${pct} % · ${job.stage || "starting"}${etaText(job) ? ` · ${etaText(job)}` : ""}`;
    return el("li", { "data-job": job.id },
      el("a", { href: "/jobs/" + job.id }, el("b", {}, seqName(job)), " · ", job.preset), " ", statusBadge(job.status),
      job.status === "running" ? el("progress", { max: 1, value: job.progress || 0 }) : null,
      el("div", { class: "muted small" }, state));
  }

  function recentItem(job) {
    const ate = job.metrics && job.metrics.ate ? job.metrics.ate.rmse : null;
    const facts = [
      job.status === "succeeded" && isNum(ate) ? `ATE ${metres(ate)}` : null,
      job.status === "succeeded" && job.metrics && isNum(job.metrics.fps) ? `${job.metrics.fps.toFixed(1)} frames/s` : null,
      `took ${seconds(jobDuration(job))}`, `ended ${when(job.finished_at)}`,
    ].filter(Boolean);
    return el("li", { "data-job": job.id },
      el("a", { href: "/jobs/" + job.id }, el("b", {}, seqName(job)), " · ", job.preset), " ", statusBadge(job.status),
      job.batch_id ? el("a", { href: "/batches/" + job.batch_id, class: "small" }, " batch") : null,
      el("div", { class: "muted small" }, facts.join(" · ")));
  }

  const empty = (text) => el("li", { class: "muted" }, text);
  const finishedAt = (j) => Date.parse(j.finished_at || j.created_at || 0) || 0;

  async function refresh() {
    clearTimeout(timer);
    try {
      const [running, queued, latest] = await Promise.all([
        api("/jobs?status=running&limit=10"), api("/jobs?status=queued&limit=10"), api("/jobs?limit=40")]);
      const active = [...running.items, ...queued.items.reverse()]; // queued in the order a worker takes them
      const recent = latest.items.filter((j) => TERMINAL.has(j.status)).sort((a, b) => finishedAt(b) - finishedAt(a)).slice(0, RECENT);
      await sequenceNames([...active, ...recent]);
      $("active-runs").replaceChildren(...(active.length ? active.map(activeItem) : [empty("Nothing is running.")]));
      const more = running.total + queued.total - active.length;
      $("active-count").textContent = running.total + queued.total
        ? `(${running.total} running, ${queued.total} queued${more > 0 ? `; ${more} more on the Jobs page` : ""})` : "";
      $("recent-runs").replaceChildren(...(recent.length ? recent.map(recentItem)
        : [empty("No run has finished yet: choose a sequence below and press Run.")]));
      showError($("activity-error"), null);
      timer = setTimeout(refresh, active.length ? 2500 : 15000);
    } catch (err) {
      showError($("activity-error"), err, "Could not list the runs");
      timer = setTimeout(refresh, 10000);
    }
  }
  refresh();
})();
