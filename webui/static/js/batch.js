/* Batch page: the comparison table in the paper's style (sequences x presets), live until every job ended. */
"use strict";
(() => {
  const { api, el, showError, num, metres, statusBadge, shortId, progressCell, TERMINAL, isNum } = VTD;
  const $ = (id) => document.getElementById(id);
  const main = $("main"), batchId = main.dataset.batchId, baseline = main.dataset.baseline;
  const LOWER_IS_BETTER = {
    ate_rmse: true, rpe_trans_rmse: true, rpe_rot_rmse: true, fps: false, relocalisations: true,
    ate_corrected_rmse: true, rpe_frame_trans_rmse: true, rpe_frame_rot_rmse: true,
    mask_iou: false, feature_precision: false, feature_recall: false, restoration_psnr: false,
  };
  const pct = (x) => (isNum(x) ? (100 * x).toFixed(1) + " %" : "—");
  const FORMAT = {
    ate_rmse: (x) => num(x, 4), rpe_trans_rmse: (x) => num(x, 4), rpe_rot_rmse: (x) => num(x, 3), fps: (x) => num(x, 2),
    relocalisations: (x) => num(x, 0), mask_iou: (x) => num(x, 3), feature_precision: pct, feature_recall: pct,
    restoration_psnr: (x) => num(x, 1),
    ate_corrected_rmse: (x) => num(x, 4), rpe_frame_trans_rmse: (x) => num(x, 4), rpe_frame_rot_rmse: (x) => num(x, 3),
  };
  const TRUTH = [["mask_iou", "Mask IoU"], ["feature_precision", "Dyn. feature precision"],
    ["feature_recall", "Dyn. feature recall"], ["restoration_psnr", "Restoration PSNR (dB)"], ["relocalisations", "Relocalisations"]];
  let batch = null, table = [], timer = null;

  function render() {
    const metric = $("metric").value, lower = LOWER_IS_BETTER[metric];
    const label = $("metric").selectedOptions[0].textContent;
    const presets = batch.presets;
    const rows = new Map();
    for (const r of table) {
      if (!rows.has(r.sequence_id)) rows.set(r.sequence_id, { name: r.sequence_name || r.sequence_id.slice(0, 8), cells: {} });
      rows.get(r.sequence_id).cells[r.preset] = r;
    }
    const head = el("thead", {}, el("tr", {}, el("th", {}, "Sequence"),
      ...presets.map((p) => el("th", { class: "n" }, p + (p === baseline ? " (baseline)" : "")))));
    const body = el("tbody");
    for (const [, row] of rows) {
      const vals = presets.map((p) => (row.cells[p] && isNum(row.cells[p][metric]) ? row.cells[p][metric] : null));
      const finite = vals.filter(isNum);
      const best = finite.length > 1 || (finite.length === 1 && presets.length === 1) ? (lower ? Math.min(...finite) : Math.max(...finite)) : null;
      const base = row.cells[baseline] && isNum(row.cells[baseline][metric]) ? row.cells[baseline][metric] : null;
      const tr = el("tr", {}, el("td", {}, row.name));
      presets.forEach((p, i) => {
        const cell = row.cells[p], v = vals[i];
        if (!isNum(v)) {
          const s = cell && cell.status;
          tr.append(el("td", { class: "n muted" }, cell && cell.job_id && s ? el("a", { href: "/jobs/" + cell.job_id }, s === "succeeded" ? "no value" : s) : "—"));
          return;
        }
        const td = el("td", { class: "n" + (v === best ? " best" : ""), title: `${label}: ${v}` },
          cell.job_id ? el("a", { href: "/jobs/" + cell.job_id }, FORMAT[metric](v)) : FORMAT[metric](v));
        if (isNum(base) && base !== 0 && p !== baseline) {
          const pct = (100 * (v - base)) / Math.abs(base);
          const good = lower ? pct < 0 : pct > 0;
          td.append(el("span", { class: "delta " + (Math.abs(pct) < 0.05 ? "" : good ? "better" : "worse") },
            `(${pct > 0 ? "+" : pct < 0 ? "−" : "±"}${Math.abs(pct).toFixed(1)} %)`));
        }
        tr.append(td);
      });
      body.append(tr);
    }
    if (!rows.size) body.append(el("tr", {}, el("td", { colspan: presets.length + 1, class: "muted" }, "No results yet.")));
    $("compare").replaceChildren(head, body);
    // Sequences whose ground truth is a marker's pose (Bonn): say what each figure was measured against.
    const marked = [...new Set(table.filter((r) => r.groundtruth_frame && r.groundtruth_frame !== "camera")
      .map((r) => `${r.sequence_name || r.sequence_id.slice(0, 8)} (${r.groundtruth_frame})`))];
    $("batch-gt-frame")?.remove();
    if (marked.length) $("compare").parentNode.after(el("p", { id: "batch-gt-frame", class: "muted small" },
      `Ground truth that is not the camera's pose: ${marked.join(", ")}. Its "ATE RMSE" is against that raw ground `
      + "truth (the published convention), \"ATE corrected\" and every RPE against the camera's ground truth "
      + "corrected from it."));
    $("batch-note").hidden = !presets.includes(baseline) && presets.length < 2;
  }

  /** Every truth score of every run side by side (the comparison table shows one metric at a time). */
  function truthTable() {
    const scored = table.filter((r) => TRUTH.slice(0, 4).some(([k]) => isNum(r[k])));
    $("truth-card").hidden = !scored.length;
    if (!scored.length) return;
    const multi = new Set(table.map((r) => r.sequence_id)).size > 1;
    $("truth-compare").replaceChildren(
      el("thead", {}, el("tr", {}, el("th", {}, multi ? "Sequence · preset" : "Preset"), ...TRUTH.map(([, h]) => el("th", { class: "n" }, h)))),
      el("tbody", {}, ...table.filter((r) => r.status === "succeeded").map((r) => el("tr", {},
        el("td", {}, el("a", { href: "/jobs/" + r.job_id }, multi ? `${r.sequence_name || r.sequence_id.slice(0, 8)} · ${r.preset}` : r.preset)),
        ...TRUTH.map(([k]) => el("td", { class: "n" }, FORMAT[k](r[k])))))));
  }

  function jobsTable(names) {
    $("batch-jobs").replaceChildren(...batch.jobs.map((j) => el("tr", {},
      el("td", {}, el("a", { href: "/jobs/" + j.id }, shortId(j.id))),
      el("td", {}, names.get(j.sequence_id) || j.sequence_id.slice(0, 8)),
      el("td", {}, j.preset), el("td", {}, statusBadge(j.status)), el("td", {}, progressCell(j)),
      el("td", { class: "n" }, metres(j.metrics && j.metrics.ate ? j.metrics.ate.rmse : null)))));
  }

  async function load() {
    clearTimeout(timer);
    try {
      [batch, table] = await Promise.all([api("/batches/" + batchId), api(`/batches/${batchId}/table`)]);
      $("batch-status").replaceChildren(statusBadge(batch.status));
      $("batch-name").textContent = batch.name ? `Comparison: ${batch.name}` : "Comparison";
      $("batch-title").textContent = batch.name || "";
      document.title = `${batch.name || "Batch " + batchId.slice(0, 8)} · VTD-SLAM`;
      const names = new Map(table.map((r) => [r.sequence_id, r.sequence_name || r.sequence_id.slice(0, 8)]));
      render(); jobsTable(names); truthTable();
      VTDBatchPlots.draw(table).catch((err) => showError($("batch-error"), err, "Could not draw the trajectories"));
      showError($("batch-error"), null);
      if (batch.jobs.some((j) => !TERMINAL.has(j.status))) timer = setTimeout(load, 2500);
    } catch (err) {
      showError($("batch-error"), err, err.status === 404 ? "No such batch" : "Could not load the batch");
      $("compare").replaceChildren();
      if (err.status !== 404) timer = setTimeout(load, 5000);
    }
  }
  $("metric").addEventListener("change", () => batch && render());
  VTDBatchPlots.watchChoice(() => table);
  load();
})();
