/* Batch page plots: ATE, RPE and speed per preset (bars), and one sequence's trajectories overlaid (top view). */
"use strict";
const VTDBatchPlots = (() => {
  const { api, el, num, isNum } = VTD;
  const { presetColor, parseTum, artifactText, lineChart, barChart, note } = VTDPlot;
  const $ = (id) => document.getElementById(id);
  let drawnKey = null, trajKey = null;

  /** Metres shown in mm when every value is under 10 cm (bars read better with whole numbers). */
  function lengthScale(values) {
    return Math.max(...values) < 0.1 ? { k: 1000, unit: "mm" } : { k: 1, unit: "m" };
  }

  function bars(box, rows, field, { what, unitOf }) {
    const have = rows.filter((r) => isNum(r[field]));
    if (!have.length) {
      note(box, rows.some((r) => r.status === "succeeded")
        ? `No ${what} in the finished runs' metrics (no ground truth, or too short a sequence for it).` : "Waiting for results…");
      return;
    }
    const sequences = new Set(rows.map((r) => r.sequence_id));
    const { k, unit } = unitOf(have.map((r) => r[field]));
    const presets = [...new Set(rows.map((r) => r.preset))];
    const items = have.map((r) => ({
      label: sequences.size > 1 ? `${r.sequence_name || r.sequence_id.slice(0, 8)} · ${r.preset}` : r.preset,
      value: r[field] * k,
      color: presetColor(r.preset, presets.indexOf(r.preset)),
    }));
    barChart(box, items, { unit: `${what} (${unit})`, fmt: (v) => num(v, v < 10 ? 2 : 1), ariaLabel: `${what} per preset` });
  }

  function sequenceChoice(rows) {
    const select = $("traj-seq");
    const seqs = [...new Map(rows.map((r) => [r.sequence_id, r.sequence_name || r.sequence_id.slice(0, 8)]))];
    if (select.options.length !== seqs.length) {
      const keep = select.value;
      select.replaceChildren(...seqs.map(([id, name]) => el("option", { value: id }, name)));
      if (keep && seqs.some(([id]) => id === keep)) select.value = keep;
    }
    select.hidden = seqs.length < 2;
    return select.value || (seqs[0] && seqs[0][0]);
  }

  /** The chosen sequence's estimates, one colour per preset, with the ground truth one run aligned. */
  async function trajectories(rows) {
    const seqId = sequenceChoice(rows);
    const done = rows.filter((r) => r.sequence_id === seqId && r.status === "succeeded" && r.job_id);
    const key = seqId + ":" + done.map((r) => r.job_id).join(",");
    if (key === trajKey) return;
    trajKey = key;
    const box = $("plot-traj");
    if (!done.length) { note(box, "Waiting for a finished run of this sequence…"); return; }
    const presets = [...new Set(rows.map((r) => r.preset))];
    const est = await Promise.all(done.map((r) => artifactText(r.job_id, "trajectory.txt").then(parseTum, () => [])));
    const first = done[0];
    const listed = await api(`/jobs/${first.job_id}/artifacts`).catch(() => []);
    const gt = listed.some((a) => a.name === "groundtruth_aligned.txt")
      ? await artifactText(first.job_id, "groundtruth_aligned.txt").then(parseTum, () => null) : null;
    if (trajKey !== key) return; // the choice changed while the files were loading
    // The SLAM world is the first camera's frame (y down): the ground plane is x-z.
    const series = [];
    if (gt && gt.length) {
      series.push({ pts: gt.map((p) => [p[1], p[3]]), color: "#1f2328", dash: "5 3", width: 1.2, start: true,
        label: `ground truth (aligned to ${first.preset})` });
    }
    done.forEach((r, i) => {
      if (est[i].length) series.push({ pts: est[i].map((p) => [p[1], p[3]]), color: presetColor(r.preset, presets.indexOf(r.preset)), label: r.preset, start: true });
    });
    if (!series.length) { note(box, "The finished runs wrote no trajectory."); return; }
    lineChart(box, series, { xLabel: "x (m)", yLabel: "z (m)", equal: true });
  }

  /** Redraw what changed: bars when any value did, trajectories when another run of the sequence finished. */
  function draw(rows) {
    const key = JSON.stringify(rows.map((r) => [r.job_id, r.status, r.ate_rmse, r.rpe_trans_rmse, r.fps]));
    if (key !== drawnKey) {
      drawnKey = key;
      bars($("plot-ate"), rows, "ate_rmse", { what: "ATE RMSE", unitOf: lengthScale });
      bars($("plot-rpe"), rows, "rpe_trans_rmse", { what: "RPE translation RMSE", unitOf: lengthScale });
      bars($("plot-fps"), rows, "fps", { what: "speed", unitOf: () => ({ k: 1, unit: "frames/s" }) });
    }
    return trajectories(rows);
  }

  function watchChoice(getRows) {
    $("traj-seq").addEventListener("change", () => { trajKey = null; trajectories(getRows()); });
  }

  return { draw, watchChoice };
})();
