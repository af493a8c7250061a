/* Job page: live progress, metrics table, SVG plots drawn here (no libraries), previews, downloads, 3D viewer. */
"use strict";
(() => {
  const { api, el, showError, num, metres, bytes, seconds, when, jobDuration, TERMINAL, statusBadge, followJob, isNum } = VTD;
  const $ = (id) => document.getElementById(id);
  const jobId = document.getElementById("main").dataset.jobId;
  const SVGNS = "http://www.w3.org/2000/svg";
  const COLORS = { est: "#0b6bcb", gt: "#8c959f", err: "#c2410c", bar: "#0b6bcb" };
  let seqInfo = null, resultsShown = false;

  // ---------- summary ----------
  function facts(job) {
    const m = job.metrics || {};
    const items = [
      ["Sequence", seqInfo ? seqInfo.name : job.sequence_id.slice(0, 8)],
      ["Ground truth", seqInfo ? (seqInfo.has_groundtruth ? "yes" : "no") : "—"],
      ["Preset", job.preset],
      ["Stage", job.status === "running" ? job.stage || "—" : job.status === "queued" ? "waiting" : job.status === "succeeded" ? "finished" : "stopped"],
      ["Frames", job.frames_total ? `${job.frames_done} of ${job.frames_total}` : "—"],
      ["Queued", when(job.created_at)],
      ["Run time", seconds(jobDuration(job))],
      ["Headline ATE RMSE", m.ate ? metres(m.ate.rmse) : "—"],
      ["Worker", job.worker || "—"],
    ];
    if (m.device) items.push(["Device", m.device]);
    if (job.batch_id) items.push(["Batch", el("a", { href: "/batches/" + job.batch_id }, job.batch_id.slice(0, 8))]);
    $("facts").replaceChildren(...items.map(([k, v]) => el("div", {}, el("dt", {}, k), el("dd", {}, v))));
    $("job-status").replaceChildren(statusBadge(job.status));
    const running = !TERMINAL.has(job.status);
    $("job-progress").hidden = !running;
    if (running) {
      $("job-bar").value = job.progress || 0;
      const eta = isNum(job.eta_s) ? ` · about ${seconds(job.eta_s)} left` : "";
      $("job-progress-text").textContent = job.status === "queued" ? "waiting for a worker"
        : `${Math.round(100 * (job.progress || 0))} % · ${job.stage}${eta}`;
    }
    if (job.status === "failed" || job.status === "cancelled") {
      showError($("job-error"), new Error(job.error || job.status), job.status === "failed" ? "The run failed" : "Cancelled");
    } else showError($("job-error"), null);
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
    stats("ATE, absolute trajectory error (m)", m.ate, (x) => num(x, 4));
    if (m.rpe) {
      stats("RPE translation (m per interval)", m.rpe.trans, (x) => num(x, 4));
      stats("RPE rotation (° per interval)", m.rpe.rot_deg || m.rpe.rot, (x) => num(x, 3));
    }
    const head = el("thead", {}, el("tr", {}, ...["Error", "RMSE", "Mean", "Median", "Std", "Max"].map((h, i) => el("th", { class: i ? "n" : "" }, h))));
    const body = el("tbody", {}, ...rows.map((r) => el("tr", {}, ...r.map((c, i) => el("td", { class: i ? "n" : "" }, c)))));
    const singles = [
      ["Frames", m.frames, 0, "frames"], ["Tracked", m.tracked, 0, "frames"], ["Lost", m.lost, 0, "frames"],
      ["Relocalisations", m.relocalisations, 0, ""], ["Keyframes", m.keyframes, 0, ""], ["Loops closed", m.loops_applied, 0, ""],
      ["Poses matched to ground truth", m.matched_poses, 0, ""], ["Speed, whole pipeline", m.fps, 2, "frames/s"],
      ["Speed, tracking only", m.tracking_fps, 2, "frames/s"], ["Map points", m.map_points, 0, ""],
      ["Dense map points", m.dense_points, 0, ""], ["Peak memory", m.peak_rss_mb, 1, "MB"],
    ].filter((r) => isNum(r[1]));
    const body2 = el("tbody", {}, ...singles.map(([k, v, d, u]) => el("tr", {}, el("td", {}, k), el("td", { class: "n", colspan: 5 }, num(v, d, u)))));
    const t = $("metrics-table");
    t.replaceChildren(...(rows.length ? [head, body] : []), body2);
    if (m.evaluation_error) t.after(el("p", { class: "muted" }, "No ATE/RPE: " + m.evaluation_error));
  }

  // ---------- data files ----------
  function parseTum(text) {
    const out = [];
    for (const line of text.split("\n")) {
      if (!line.trim() || line.startsWith("#")) continue;
      const v = line.trim().split(/[\s,]+/).map(Number);
      if (v.length >= 4 && v.slice(0, 4).every(isFinite)) out.push(v);
    }
    return out; // [t, x, y, z, qx, qy, qz, qw]
  }
  function parseCsv(text) {
    const lines = text.trim().split("\n");
    const head = lines.shift().split(",").map((s) => s.trim());
    return lines.map((l) => { const v = l.split(","); const o = {}; head.forEach((h, i) => { o[h] = v[i]; }); return o; });
  }
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

  // ---------- SVG plotting ----------
  const svgEl = (tag, attrs = {}, text) => {
    const n = document.createElementNS(SVGNS, tag);
    for (const [k, v] of Object.entries(attrs)) n.setAttribute(k, v);
    if (text !== undefined) n.textContent = text;
    return n;
  };
  function ticks(lo, hi, n = 5) {
    const span = hi - lo || 1, raw = span / n, p = Math.pow(10, Math.floor(Math.log10(raw)));
    const step = [1, 2, 2.5, 5, 10].map((k) => k * p).find((s) => span / s <= n) || 10 * p;
    const out = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(+v.toPrecision(12));
    return { values: out, step };
  }
  /** Tick labels with as many decimals as the step needs (0.0025 -> 4, 0.5 -> 1, 20 -> 0). */
  function tickText(v, step) {
    const s = String(+step.toPrecision(6)), i = s.indexOf(".");
    return v.toFixed(s.includes("e") ? 6 : i < 0 ? 0 : s.length - i - 1);
  }
  function extent(values, pad = 0.04) {
    let lo = Math.min(...values), hi = Math.max(...values);
    if (!isFinite(lo)) { lo = 0; hi = 1; }
    if (hi - lo < 1e-9) { lo -= 0.5; hi += 0.5; }
    const d = (hi - lo) * pad;
    return [lo - d, hi + d];
  }

  /** A line chart: series = [{pts: [[x, y]], color, label, dash}]; `equal` keeps metres square (top views). */
  const widthOf = (box) => Math.max(320, Math.round(box.clientWidth || 460));
  function lineChart(box, series, { xLabel, yLabel, equal = false, yZero = false } = {}) {
    const W = widthOf(box), H = Math.round(W * 0.66);
    const M = { l: 58, r: 14, t: 10, b: 42 };
    const xs = series.flatMap((s) => s.pts.map((p) => p[0])), ys = series.flatMap((s) => s.pts.map((p) => p[1]));
    let [x0, x1] = extent(xs), [y0, y1] = extent(ys);
    if (yZero) y0 = Math.min(0, y0);
    const pw = W - M.l - M.r, ph = H - M.t - M.b;
    if (equal) { // same metres per pixel on both axes
      const s = Math.max((x1 - x0) / pw, (y1 - y0) / ph);
      const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
      [x0, x1, y0, y1] = [cx - s * pw / 2, cx + s * pw / 2, cy - s * ph / 2, cy + s * ph / 2];
    }
    const X = (x) => M.l + (x - x0) / (x1 - x0) * pw, Y = (y) => M.t + ph - (y - y0) / (y1 - y0) * ph;
    const svg = svgEl("svg", { viewBox: `0 0 ${W} ${H}`, role: "img", "aria-label": `${yLabel} against ${xLabel}` });
    const grid = svgEl("g", { class: "grid" }), axis = svgEl("g", { class: "axis" });
    const tx = ticks(x0, x1, 6), ty = ticks(y0, y1, 5);
    for (const v of tx.values) {
      grid.append(svgEl("line", { x1: X(v), x2: X(v), y1: M.t, y2: M.t + ph }));
      axis.append(svgEl("text", { x: X(v), y: M.t + ph + 14, "text-anchor": "middle" }, tickText(v, tx.step)));
    }
    for (const v of ty.values) {
      grid.append(svgEl("line", { x1: M.l, x2: M.l + pw, y1: Y(v), y2: Y(v) }));
      axis.append(svgEl("text", { x: M.l - 6, y: Y(v) + 4, "text-anchor": "end" }, tickText(v, ty.step)));
    }
    axis.append(svgEl("path", { d: `M${M.l},${M.t}V${M.t + ph}H${M.l + pw}`, fill: "none" }));
    axis.append(svgEl("text", { x: M.l + pw / 2, y: H - 6, "text-anchor": "middle" }, xLabel));
    axis.append(svgEl("text", { x: 12, y: M.t + ph / 2, "text-anchor": "middle", transform: `rotate(-90 12 ${M.t + ph / 2})` }, yLabel));
    svg.append(grid, axis);
    for (const s of series) {
      if (!s.pts.length) continue;
      const d = s.pts.map((p, i) => (i ? "L" : "M") + X(p[0]).toFixed(1) + "," + Y(p[1]).toFixed(1)).join("");
      svg.append(svgEl("path", { d, fill: "none", stroke: s.color, "stroke-width": s.width || 1.8,
        "stroke-dasharray": s.dash || "none", "stroke-linejoin": "round", class: "series", "data-label": s.label }));
      if (s.start) svg.append(svgEl("circle", { cx: X(s.pts[0][0]), cy: Y(s.pts[0][1]), r: 3.5, fill: s.color }));
    }
    box.replaceChildren(svg, legend(series));
  }
  const legend = (series) => el("div", { class: "legend" }, ...series.filter((s) => s.label).map((s) => {
    const i = el("i"); i.style.background = s.color; if (s.dash) i.style.opacity = ".7";
    return el("span", {}, i, s.label);
  }));

  /** Horizontal bars: items = [[label, value]]; unit appended to the value labels. */
  function barChart(box, items, unit) {
    const W = widthOf(box);
    const rowH = 26, M = { l: 110, r: 70, t: 6, b: 38 }, H = M.t + M.b + rowH * items.length;
    const max = Math.max(...items.map((i) => i[1]), 1e-9), pw = W - M.l - M.r;
    const step = ticks(0, max, 4).step, top = Math.ceil(max / step - 1e-9) * step;
    const tx = ticks(0, top, 4);
    const X = (v) => M.l + v / top * pw;
    const svg = svgEl("svg", { viewBox: `0 0 ${W} ${H}`, role: "img", "aria-label": "time per stage" });
    const grid = svgEl("g", { class: "grid" }), axis = svgEl("g", { class: "axis" });
    for (const v of tx.values) {
      grid.append(svgEl("line", { x1: X(v), x2: X(v), y1: M.t, y2: H - M.b }));
      axis.append(svgEl("text", { x: X(v), y: H - M.b + 14, "text-anchor": "middle" }, tickText(v, tx.step)));
    }
    axis.append(svgEl("text", { x: M.l + pw / 2, y: H - 2, "text-anchor": "middle" }, unit));
    svg.append(grid, axis);
    items.forEach(([label, v], k) => {
      const y = M.t + k * rowH;
      svg.append(svgEl("text", { x: M.l - 8, y: y + rowH / 2 + 4, "text-anchor": "end" }, label.replace(/_/g, " ")));
      svg.append(svgEl("rect", { x: M.l, y: y + 4, width: Math.max(1, X(v) - M.l), height: rowH - 8, fill: COLORS.bar, rx: 2, class: "bar" }));
      svg.append(svgEl("text", { x: X(v) + 5, y: y + rowH / 2 + 4 }, num(v, v < 10 ? 2 : 1) + " ms"));
    });
    box.replaceChildren(svg);
  }
  const note = (box, text) => box.replaceChildren(el("p", { class: "muted" }, text));

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
  async function fetchText(name) {
    const res = await fetch(`${VTD.API}/jobs/${jobId}/artifacts/${encodeURIComponent(name)}`);
    if (!res.ok) throw VTD.errorFrom(res.status, await res.text());
    return res.text();
  }
  const DESCRIBE = {
    "trajectory.txt": "estimated camera poses T_WC, TUM format", "keyframes.txt": "keyframe poses, TUM format",
    "map.ply": "dense point cloud of the static scene", "metrics.json": "ATE, RPE, speed, timings",
    "config.json": "full pipeline configuration used", "frames.csv": "per-frame statistics",
    "frame_stats.csv": "per-frame statistics", "groundtruth_aligned.txt": "ground truth in the estimate's frame",
    "log.txt": "the worker's log of this run", "preview.png": "trajectory sketch (top view)",
  };

  async function results(job) {
    let artifacts = [];
    try { artifacts = await api(`/jobs/${jobId}/artifacts`); } catch (err) { showError($("job-error"), err, "Could not list the outputs"); }
    const names = new Set(artifacts.map((a) => a.name));
    $("results").hidden = false;
    downloads(artifacts);
    if (job.status !== "succeeded") {
      for (const s of document.querySelectorAll("#results > section:not(:last-child)")) s.hidden = true;
      return;
    }
    const m = job.metrics || {};
    metricsTable(m);
    const timings = Object.entries(m.timings_ms || {}).filter(([, v]) => isNum(v));
    if (timings.length) barChart($("plot-timing"), timings, "mean time per call (ms)");
    else note($("plot-timing"), "This run recorded no stage timings.");
    previews(artifacts.filter((a) => /\.(png|jpe?g)$/i.test(a.name) && a.name !== "preview.png")); // that one is a trajectory sketch

    const fname = names.has("frame_stats.csv") ? "frame_stats.csv" : names.has("frames.csv") ? "frames.csv" : null;
    const optional = (name, parse) => (names.has(name) ? fetchText(name).then(parse, () => null) : Promise.resolve(null));
    let [est, gt, frames] = await Promise.all([ // in parallel: the plots appear after one round trip
      fetchText("trajectory.txt").then(parseTum, (err) => { note($("plot-traj"), "No trajectory: " + err.message); return []; }),
      optional("groundtruth_aligned.txt", parseTum),
      optional(fname, parseCsv),
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

  function previews(images) {
    if (!images.length) return;
    $("previews-card").hidden = false;
    $("previews").replaceChildren(...images.map((a) => el("figure", {},
      el("a", { href: a.url, target: "_blank" }, el("img", { src: a.url, alt: a.name, loading: "lazy" })),
      el("figcaption", {}, a.name.replace(/\.(png|jpe?g)$/i, "").replace(/_/g, " ")))));
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
