/* Job page, while the job runs: its partial results (GET /jobs/{id}/partial, worker/snapshots.py), polled. */
"use strict";
(() => {
  const { api, el, showError, num, TERMINAL } = VTD;
  const { lineChart } = VTDPlot;
  const $ = (id) => document.getElementById(id);
  const jobId = document.getElementById("main").dataset.jobId;
  const POLL_MS = 500;
  const path = new Map(); // frame index -> [x, y, z] of every pose seen so far
  let lastImage = 0, lastDrawn = 0;

  function show(p) {
    const s = p.state;
    $("live-card").hidden = false;
    if (!s) { $("live-facts").replaceChildren(el("div", {}, el("dt", {}, "Frames"), el("dd", {}, "waiting for the first frame"))); return; }
    for (const r of s.recent) if (r.tracked) path.set(r.index, r.position);
    const last = s.recent[s.recent.length - 1];
    const delays = s.recent.filter((r) => r.arrival).map((r) => 1000 * (r.done - r.arrival));
    const items = [["Frames run", String(s.frames)], ["Tracked", String(s.tracked)], ["Keyframes", String(s.run_keyframes ?? "—")],
      ["Map points", String(s.map_points ?? 0)]];
    if (s.frames_received !== undefined) {
      items.push(["Received", String(s.frames_received)], ["Dropped", String(s.frames_dropped)]);
    }
    if (last) items.push(["Latest pose", `frame ${last.index}: ${last.position.map((v) => num(v, 3)).join(", ")} m`]);
    if (delays.length) items.push(["Arrival to pose", `${num(delays[delays.length - 1], 0)} ms`]);
    $("live-facts").replaceChildren(...items.map(([k, v]) => el("div", {}, el("dt", {}, k), el("dd", {}, v))));
    if (s.updated - lastImage >= 1) { // the image is rewritten about once a second
      lastImage = s.updated;
      const img = el("img", { id: "live-frame", alt: "the latest frame with its masks", style: "max-width: 100%" });
      img.onload = () => $("live-frame-box").replaceChildren(img); // swapped in once loaded: no flicker
      img.src = `/api/v1/jobs/${jobId}/artifacts/partial_frame_mask.jpg?t=${s.updated}`;
      // the classes in that frame, in their colours (worker/snapshots.py: partial.json's frame_legend)
      if (window.VTDClasses) $("live-legend").replaceChildren(VTDClasses.legend(s.frame_legend));
    }
    if (path.size >= 2 && path.size !== lastDrawn) {
      lastDrawn = path.size;
      const pts = [...path.entries()].sort((a, b) => a[0] - b[0]).map(([, p]) => [p[0], p[2]]);
      lineChart($("live-traj"), [{ pts, color: "#0b6bcb", label: "estimate so far", start: true }], { xLabel: "x (m)", yLabel: "z (m)", equal: true });
    }
  }

  async function poll() {
    try {
      const p = await api(`/jobs/${jobId}/partial`);
      // done, or the results already on the page (job.js saw the end first): the card goes and polling stops
      if (TERMINAL.has(p.status) || !$("results").hidden) { $("live-card").hidden = true; return; }
      if (p.status === "running") show(p);
    } catch (_) { /* the next poll tries again */ }
    setTimeout(poll, POLL_MS);
  }

  $("live-viewer-btn").addEventListener("click", async () => {
    showError($("live-viewer-error"), null);
    try {
      const v = await api(`/jobs/${jobId}/viewer`);
      $("live-viewer").src = v.url;
      $("live-viewer-wrap").hidden = false;
    } catch (err) { showError($("live-viewer-error"), err, "The 3D viewer could not open the run yet"); }
  });
  poll();
})();
