/* Job page: live progress, metrics table, SVG plots drawn here (no libraries), previews, downloads, 3D viewer. */
"use strict";
(() => {
  const { api, el, showError, num, metres, bytes, seconds, when, jobDuration, TERMINAL, statusBadge, followJob, isNum, etaText } = VTD;
  const { parseTum, parseCsv, lineChart, barChart, note } = VTDPlot;
  const $ = (id) => document.getElementById(id);
  const jobId = document.getElementById("main").dataset.jobId;
  const COLORS = { est: "#0b6bcb", gt: "#8c959f", err: "#c2410c", bar: "#0b6bcb" };
  let seqInfo = null, resultsShown = false;

  // ---------- summary ----------
  function facts(job) {
    const m = job.metrics || {};
    const items = [
      ["Sequence", seqInfo ? seqInfo.name : job.sequence_id.slice(0, 8)],
      ["Ground truth", seqInfo ? (!seqInfo.has_groundtruth ? "no" : seqInfo.groundtruth_frame && seqInfo.groundtruth_frame !== "camera" ? `yes, the ${seqInfo.groundtruth_frame}'s pose` : "yes") : "—"],
      ["Preset", job.preset],
      ["Stage", job.status === "running" ? job.stage || "—" : job.status === "queued" ? "waiting" : job.status === "succeeded" ? "finished" : job.status === "cancelled" ? "cancelled" : job.status === "failed" && job.stage ? `failed at ${job.stage}` : "stopped"],
      ["Frames", job.frames_total ? `${job.frames_done} of ${job.frames_total}` : "—"],
      ["Queued", when(job.created_at)],
      ["Run time", seconds(jobDuration(job))],
      ["Headline ATE RMSE", m.ate ? metres(m.ate.rmse) : "—"],
      ["Worker", job.worker || "—"],
    ];
    if (m.device) items.push(["Device", m.device]);
    // the code that produced the figures (metrics.json's version and git commit; older runs have neither)
    if (typeof m.version === "string") {
      const commit = typeof m.commit === "string" ? m.commit : "";
      items.push(["Code version", el("span", { id: "code-version", title: commit ? "git commit " + commit : "not run from a git checkout" },
        commit ? `${m.version} · commit ${commit.slice(0, 12)}` : m.version)]);
    }
    if (job.batch_id) items.push(["Batch", el("a", { href: "/batches/" + job.batch_id }, job.batch_id.slice(0, 8))]);
    $("facts").replaceChildren(...items.map(([k, v]) => el("div", {}, el("dt", {}, k), el("dd", {}, v))));
    $("job-status").replaceChildren(statusBadge(job.status));
    const running = !TERMINAL.has(job.status);
    $("job-progress").hidden = !running;
    if (running) {
      $("job-bar").value = job.progress || 0;
      const eta = etaText(job) ? ` · ${etaText(job)}` : "";
      $("job-progress-text").textContent = job.status === "queued" ? "waiting for a worker"
        : `${Math.round(100 * (job.progress || 0))} % · ${job.stage}${eta}`;
    }
    // A failure is an error; a cancel is what someone asked for: said plainly, in the neutral note.
    if (job.status === "failed") showError($("job-error"), new Error(job.error || "no reason given"), "The run failed");
    else showError($("job-error"), null);
    const cancelled = $("job-cancelled");
    cancelled.hidden = job.status !== "cancelled";
    cancelled.textContent = job.status === "cancelled"
      ? `Cancelled${job.frames_done ? ` at frame ${job.frames_done} of ${job.frames_total}` : " before it started"}`
        + (job.error ? ` (${job.error})` : "") + ". Retry runs it again from the start." : "";
    const acts = [];
    const act = (label, path, method = "POST", after) => el("button", { type: "button", onclick: async () => {
      if (method === "DELETE" && !confirm("Delete this job and its files?")) return;
      try { const j = await api(`/jobs/${jobId}${path}`, { method }); if (after) after(j); else start(); }
      catch (err) { showError($("job-error"), err, label + " failed"); }
    } }, label);
    if (running) acts.push(act("Cancel", "/cancel"));
    else if (job.status !== "succeeded") acts.push(act("Retry", "/retry"));
    acts.push(act("Delete", "", "DELETE", () => { location.href = "/jobs"; }));
    $("job-actions").replaceChildren(...acts);
    if (TERMINAL.has(job.status) && !resultsShown) { resultsShown = true; results(job); }
  }

  // ---------- metrics ----------
  function metricsTable(m) {
    const rows = [];
    const stats = (label, o, fmt) => {
      if (!o || typeof o !== "object") return;
      rows.push([label, ...["rmse", "mean", "median", "std", "max"].map((k) => fmt(o[k]))]);
    };
    // What each figure was measured against (metrics.json's labels; runs made before them say nothing).
    const against = (label) => (typeof label === "string" ? `, against ${label}` : "");
    const marker = typeof m.groundtruth_frame === "string" && m.groundtruth_frame !== "camera";
    stats(`ATE, absolute trajectory error (m)${against(m.ate_against)}`, m.ate, (x) => num(x, 4));
    if (marker) stats(`ATE corrected (m)${against(m.ate_corrected_against)}`, m.ate_corrected, (x) => num(x, 4));
    const per = (r) => (r && isNum(r.delta_s) ? `per ${num(r.delta_s, r.delta_s % 1 ? 2 : 0)} s` : "per interval");
    if (m.rpe) {
      stats(`RPE translation (m ${per(m.rpe)})${against(m.rpe_against)}`, m.rpe.trans, (x) => num(x, 4));
      stats(`RPE rotation (° ${per(m.rpe)})${against(m.rpe_against)}`, m.rpe.rot_deg, (x) => num(x, 3));
    }
    if (m.rpe_frame) {
      stats(`RPE translation (m per frame)${against(m.rpe_against)}`, m.rpe_frame.trans, (x) => num(x, 4));
      stats(`RPE rotation (° per frame)${against(m.rpe_against)}`, m.rpe_frame.rot_deg, (x) => num(x, 3));
    }
    const head = el("thead", {}, el("tr", {}, ...["Error", "RMSE", "Mean", "Median", "Std", "Max"].map((h, i) => el("th", { class: i ? "n" : "" }, h))));
    const body = el("tbody", {}, ...rows.map((r) => el("tr", {}, ...r.map((c, i) => el("td", { class: i ? "n" : "" }, c)))));
    const singles = [
      ["Frames", m.frames, 0, "frames"], ["Tracked", m.tracked, 0, "frames"], ["Lost", m.lost, 0, "frames"],
      ["Relocalisations", m.relocalisations, 0, ""], ["New maps after a loss", m.new_maps, 0, ""],
      ["Maps merged back", m.map_merges, 0, ""], ["Poses from established points", m.established_switches, 0, ""],
      ["Frames rescued by held-back keypoints", m.rescued_frames, 0, ""],
      ["Frames re-extracted around moving objects", dig(m, "culling", "frames_refilled"), 0, ""],
      ["Keyframes", m.keyframes, 0, ""], ["Frames re-solved against the final map", m.frames_refit, 0, ""],
      ["Frames moved by the end-of-run smoothing", m.frames_smoothed, 0, ""],
      ["Loops closed", m.loops_applied, 0, ""],
      ["Poses matched to ground truth", m.matched_poses, 0, ""], ["Speed, whole pipeline", m.fps, 2, "frames/s"],
      ["Speed, tracking only", m.tracking_fps, 2, "frames/s"], ["Map points", m.map_points, 0, ""],
      ["Observations added by map-point fusion", m.fused_observations, 0, ""],
      ["Reference poses refined for restoration", dig(m, "restoration", "reference_poses_refined"), 0, ""],
      ["Dense map points", m.dense_points, 0, ""], ["Peak memory", m.peak_rss_mb, 1, "MB"],
    ].filter((r) => isNum(r[1]));
    // Counts and speeds in a two-column table of their own: on a phone it fits, while the wide error table scrolls.
    $("metrics-counts").replaceChildren(el("tbody", {}, ...singles.map(([k, v, d, u]) => el("tr", {}, el("td", {}, k), el("td", { class: "n" }, num(v, d, u))))));
    const t = $("metrics-table");
    t.replaceChildren(...(rows.length ? [head, body] : []));
    t.hidden = !rows.length;
    if (m.evaluation_error) t.after(el("p", { class: "muted" }, "No ATE/RPE: " + m.evaluation_error));
    $("metrics-gt-frame")?.remove();
    if (marker && rows.length) t.parentNode.after(el("p", { id: "metrics-gt-frame", class: "muted small" },
      `This sequence's ground truth is the pose of its ${m.groundtruth_frame}, not of the camera. ATE is given against it `
      + "(the published convention) and against the camera's ground truth corrected from it; RPE only against the "
      + "camera's, since against the marker it would measure the marker's lever arm rather than tracking."));
    // frames that were not tracked: trajectory.txt and the ATE hold only the tracked ones
    $("metrics-warnings")?.remove();
    const warnings = Array.isArray(m.warnings) ? m.warnings.filter((w) => typeof w === "string") : [];
    if (warnings.length) $("metrics-counts").parentNode.before(el("p", { id: "metrics-warnings", class: "note warn" }, warnings.join(" ")));
  }

  // ---------- scores against truth (sequences made with truth: vtdslam synth / augment) ----------
  const dig = (o, ...path) => path.reduce((x, k) => (x && typeof x === "object" ? x[k] : undefined), o);
  const pct = (x) => (isNum(x) ? (100 * x).toFixed(1) + " %" : "—");
  const TRUTH = [
    ["Mask IoU", "the culled region against the true moving-object masks", ["culling", "truth", "mask_iou"], (x) => num(x, 3)],
    ["Dynamic-feature precision", "of the features removed, the share that lay on true movers", ["culling", "truth", "feature_precision"], pct],
    ["Dynamic-feature recall", "of the features on true movers, the share removed", ["culling", "truth", "feature_recall"], pct],
    ["Missed by culling", "of the features on true movers, the share segmentation marked but culling kept", ["culling", "truth", "feature_missed_by_culling"], pct],
    ["Missed by segmentation", "of the features on true movers, the share segmentation never marked", ["culling", "truth", "feature_missed_by_segmentation"], pct],
    ["Restoration PSNR", "restored pixels against the true background", ["restoration", "truth", "restoration_psnr"], (x) => num(x, 1, "dB")],
    ["Restored depth, median error", "restored depth against the true background's", ["restoration", "truth", "restoration_depth_median_m"], metres],
  ];
  function truthTable(m) {
    const rows = TRUTH.filter(([, , path]) => isNum(dig(m, ...path)));
    const byClass = VTDClasses.recallTable(m);
    $("truth-by-class-box").replaceChildren(...(byClass ? [el("h3", {}, "By true mover class"),
      el("p", { class: "muted small" }, "Of each class's truly moving pixels, the share segmentation marked potentially dynamic and the share culling judged moving."),
      byClass] : []));
    $("truth-card").hidden = !rows.length && !byClass;
    if (!rows.length) return;
    const scored = dig(m, "culling", "truth", "frames_scored") || {};
    $("truth-table").replaceChildren(
      el("thead", {}, el("tr", {}, el("th", {}, "Score"), el("th", { class: "n" }, "Value"), el("th", {}, "What it measures"))),
      el("tbody", {}, ...rows.map(([label, what, path, fmt]) => el("tr", {},
        el("td", {}, label), el("td", { class: "n" }, fmt(dig(m, ...path))), el("td", { class: "muted small" }, what)))));
    $("truth-note").textContent = isNum(scored.mask) ? `Culling scored on ${scored.mask} frames.` : "";
  }

  // ---------- segmentation classes (metrics.json's segmentation section) ----------
  function classesCard(m) {
    const seg = m.segmentation;
    if (!seg || typeof seg !== "object" || seg.source !== "network") return;
    $("classes-card").hidden = false;
    const dyn = Array.isArray(seg.dynamic_classes) ? seg.dynamic_classes.join(", ") : "—";
    $("classes-note").textContent = `${seg.backend || "segmenter"}: ${Array.isArray(seg.classes) ? seg.classes.length : "?"} classes; `
      + `potentially dynamic: ${dyn || "none"}. The classes seen, in the colours the frames and the 3D viewer use:`;
    $("classes-legend").replaceChildren(VTDClasses.legend(seg.legend));
    const table = VTDClasses.shareTable(seg);
    $("classes-share").replaceChildren(...(table ? [table] : [el("p", { class: "muted" }, "No class covered any pixel.")]));
    $("previews-legend").replaceChildren(VTDClasses.legend(seg.legend));
  }

  // ---------- data files ----------
  /** Per-pose error: the frames file's ate_error, else distance to the aligned ground truth at the same time. */
  function perFrameError(est, gt, frames) {
    if (frames && frames.length && frames.some((r) => r.ate_error !== undefined && r.ate_error !== "")) {
      return frames.filter((r) => r.ate_error !== "" && isFinite(+r.ate_error)).map((r) => [+r.timestamp, +r.ate_error]);
    }
    if (!gt || !gt.length) return null;
    const out = []; let j = 0;
    for (const p of est) {
      while (j + 1 < gt.length && Math.abs(gt[j + 1][0] - p[0]) <= Math.abs(gt[j][0] - p[0])) j++;
      if (Math.abs(gt[j][0] - p[0]) > 0.02) continue;
      out.push([p[0], Math.hypot(p[1] - gt[j][1], p[2] - gt[j][2], p[3] - gt[j][3])]);
    }
    return out.length ? out : null;
  }

  /** Top view: the SLAM world is the first camera's frame (y down), so the ground plane is x-z. */
  function topView(est, gt) {
    const [a, b] = [1, 3];
    const names = { 1: "x", 2: "y", 3: "z" };
    const series = [];
    if (gt && gt.length) series.push({ pts: gt.map((p) => [p[a], p[b]]), color: COLORS.gt, label: "ground truth (aligned)", dash: "5 3", start: true });
    series.push({ pts: est.map((p) => [p[a], p[b]]), color: COLORS.est, label: "estimate", start: true });
    lineChart($("plot-traj"), series, { xLabel: names[a] + " (m)", yLabel: names[b] + " (m)", equal: true });
  }

  // ---------- results ----------
  const fetchText = (name) => VTDPlot.artifactText(jobId, name);
  const DESCRIBE = {
    "trajectory.txt": "estimated camera poses T_WC, TUM format", "keyframes.txt": "keyframe poses, TUM format",
    "map.ply": "dense point cloud of the static scene", "metrics.json": "ATE, RPE, speed, timings",
    "config.json": "full pipeline configuration used",
    "frame_stats.csv": "per-frame statistics", "groundtruth_aligned.txt": "ground truth in the estimate's frame",
    "log.txt": "the worker's log of this run", "preview.png": "trajectory sketch (top view)",
    "plot_trajectory_top.png": "figure: trajectory, top view", "plot_xyz.png": "figure: x, y, z over time",
    "plot_ate_error.png": "figure: error per pose over time", "plot_timings.png": "figure: time per stage",
  };
  const isFigure = (name) => /^plot_[a-z0-9_]+\.png$/.test(name); // formats.artifacts.FIGURES

  async function results(job) {
    let artifacts = [];
    try { artifacts = await api(`/jobs/${jobId}/artifacts`); } catch (err) { showError($("job-error"), err, "Could not list the outputs"); }
    const names = new Set(artifacts.map((a) => a.name));
    // the results replace the "While it runs" card (live.js polls on its own clock and may not have seen the end)
    if ($("live-card")) $("live-card").hidden = true;
    $("results").hidden = false;
    downloads(artifacts);
    if (job.status !== "succeeded") {
      for (const s of document.querySelectorAll("#results > section:not(:last-child)")) s.hidden = true;
      return;
    }
    const m = job.metrics || {};
    metricsTable(m);
    truthTable(m);
    classesCard(m);
    const timings = Object.entries(m.timings_ms || {}).filter(([, v]) => isNum(v));
    if (timings.length) {
      barChart($("plot-timing"), timings.map(([k, v]) => ({ label: k.replace(/_/g, " "), value: v })),
        { unit: "mean time per call (ms)", fmt: (v) => num(v, v < 10 ? 2 : 1) + " ms", ariaLabel: "time per stage" });
    } else note($("plot-timing"), "This run recorded no stage timings.");
    previews(artifacts.filter((a) => /\.(png|jpe?g)$/i.test(a.name) && a.name !== "preview.png" && !isFigure(a.name))); // that one is a trajectory sketch
    figures(artifacts.filter((a) => isFigure(a.name)));

    const optional = (name, parse) => (names.has(name) ? fetchText(name).then(parse, () => null) : Promise.resolve(null));
    let [est, gt, frames] = await Promise.all([ // in parallel: the plots appear after one round trip
      fetchText("trajectory.txt").then(parseTum, (err) => { note($("plot-traj"), "No trajectory: " + err.message); return []; }),
      optional("groundtruth_aligned.txt", parseTum),
      optional("frame_stats.csv", parseCsv), // formats.frame_stats: timestamp (s), ate_error (m) per frame
    ]);
    if (est.length) topView(est, gt);
    const t0 = est.length ? est[0][0] : 0;
    const errs = perFrameError(est, gt, frames);
    if (errs) {
      const k = Math.max(...errs.map((e) => e[1])) < 0.1 ? 1000 : 1; // small errors read better in mm
      const series = [{ pts: errs.map(([t, e]) => [t - t0, e * k]), color: COLORS.err, label: "error per pose" }];
      if (m.ate && isNum(m.ate.rmse)) series.push({ pts: [[errs[0][0] - t0, m.ate.rmse * k], [errs[errs.length - 1][0] - t0, m.ate.rmse * k]], color: COLORS.gt, dash: "4 3", label: `RMSE ${metres(m.ate.rmse)}`, width: 1.2 });
      lineChart($("plot-ate"), series, { xLabel: "time since first frame (s)", yLabel: k === 1 ? "error (m)" : "error (mm)", yZero: true });
    } else if (seqInfo && !seqInfo.has_groundtruth) note($("plot-ate"), "The sequence has no ground truth, so there is no trajectory error to plot.");
    else note($("plot-ate"), m.ate ? `Overall ATE RMSE ${metres(m.ate.rmse)}; this run's outputs have no per-frame error (no groundtruth_aligned.txt or ate_error column).`
      : "No trajectory error for this run.");
    performance.mark("vtd-plots-drawn"); // read by the browser test (time until the plots are on screen)
  }

  // A frame's previews (formats.artifacts.frame_image: frame_000012_rgb.jpg) in the order a reader follows them:
  // the input, its segmentation classes, the mask culled from it, the frame restored behind it; by frame, unknown
  // kinds last by name.
  const PREVIEW_KINDS = ["rgb", "classes", "mask", "restored"];
  function previewKey(name) {
    const m = /^frame_(\d+)_([a-z]+)\./.exec(name);
    if (!m) return [Infinity, PREVIEW_KINDS.length, name];
    const k = PREVIEW_KINDS.indexOf(m[2]);
    return [+m[1], k < 0 ? PREVIEW_KINDS.length : k, name];
  }
  const byPreviewOrder = (a, b) => {
    const [x, y] = [previewKey(a.name), previewKey(b.name)];
    return x[0] - y[0] || x[1] - y[1] || (x[2] < y[2] ? -1 : x[2] > y[2] ? 1 : 0);
  };

  function previews(images) {
    if (!images.length) return;
    $("previews-card").hidden = false;
    $("previews-note").hidden = !images.some((a) => /_classes\./.test(a.name));
    $("previews").replaceChildren(...[...images].sort(byPreviewOrder).map((a) => el("figure", {},
      el("a", { href: a.url, target: "_blank" }, el("img", { src: a.url, alt: a.name, loading: "lazy" })),
      el("figcaption", {}, a.name.replace(/\.(png|jpe?g)$/i, "").replace(/_/g, " ")))));
  }

  function figures(images) {
    if (!images.length) return;
    $("figures-card").hidden = false;
    $("figures").replaceChildren(...images.map((a) => el("figure", {},
      el("a", { href: a.url, target: "_blank" }, el("img", { src: a.url, alt: DESCRIBE[a.name] || a.name, loading: "lazy" })),
      el("figcaption", {}, (DESCRIBE[a.name] || a.name).replace(/^figure: /, "")))));
  }

  function downloads(artifacts) {
    const t = $("downloads");
    if (!artifacts.length) { t.replaceChildren(el("tbody", {}, el("tr", {}, el("td", { class: "muted" }, "No files.")))); return; }
    t.replaceChildren(
      el("thead", {}, el("tr", {}, el("th", {}, "File"), el("th", {}, "Contents"), el("th", { class: "n" }, "Size"))),
      el("tbody", {}, ...artifacts.map((a) => el("tr", {},
        el("td", {}, el("a", { href: a.url, download: a.name }, a.name)),
        el("td", { class: "muted" }, DESCRIBE[a.name] || a.content_type),
        el("td", { class: "n" }, bytes(a.size_bytes))))));
  }

  // ---------- 3D viewer ----------
  $("viewer-btn").addEventListener("click", async () => {
    const btn = $("viewer-btn");
    btn.disabled = true; btn.textContent = "Opening…";
    showError($("viewer-error"), null);
    try {
      const v = await api(`/jobs/${jobId}/viewer`);
      $("viewer").src = v.url;
      $("viewer-wrap").hidden = false;
      $("viewer-link").href = v.url; $("viewer-link").hidden = false;
      btn.textContent = "Reload viewer";
    } catch (err) {
      showError($("viewer-error"), err, "The 3D viewer could not open this run");
      btn.textContent = "Open 3D viewer";
    }
    btn.disabled = false;
  });

  // ---------- start ----------
  let stop = null;
  async function start() {
    if (stop) stop();
    resultsShown = false;
    $("results").hidden = true;
    try {
      const job = await api("/jobs/" + jobId);
      try { seqInfo = await api("/sequences/" + job.sequence_id); } catch (_) { seqInfo = null; }
      facts(job);
      if (!TERMINAL.has(job.status)) stop = followJob(jobId, facts);
    } catch (err) {
      showError($("job-error"), err, err.status === 404 ? "No such job" : "Could not load the job");
      $("facts").replaceChildren();
    }
  }
  start();
})();
