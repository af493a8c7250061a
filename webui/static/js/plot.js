/* SVG charts drawn here (no libraries, nothing from another origin) and the run files they read. */
"use strict";
const VTDPlot = (() => {
  const { el, num } = VTD;
  const SVGNS = "http://www.w3.org/2000/svg";
  /** One colour per pipeline preset, the same on every page. */
  const PRESET_COLORS = { "orb-only": "#8c959f", "geometry-only": "#c2410c", "no-restoration": "#7c3aed", full: "#0b6bcb" };
  const EXTRA_COLORS = ["#1a7f37", "#b42318", "#0e7490", "#a16207"];
  const presetColor = (name, i = 0) => PRESET_COLORS[name] || EXTRA_COLORS[i % EXTRA_COLORS.length];

  // ---------- run files ----------
  /** TUM lines -> [[t, x, y, z, qx, qy, qz, qw]] (comments and short lines skipped). */
  function parseTum(text) {
    const out = [];
    for (const line of text.split("\n")) {
      if (!line.trim() || line.startsWith("#")) continue;
      const v = line.trim().split(/[\s,]+/).map(Number);
      if (v.length >= 4 && v.slice(0, 4).every(isFinite)) out.push(v);
    }
    return out;
  }
  function parseCsv(text) {
    const lines = text.trim().split("\n");
    const head = lines.shift().split(",").map((s) => s.trim());
    return lines.map((l) => { const v = l.split(","); const o = {}; head.forEach((h, i) => { o[h] = v[i]; }); return o; });
  }
  async function artifactText(jobId, name) {
    const res = await fetch(`${VTD.API}/jobs/${jobId}/artifacts/${encodeURIComponent(name)}`);
    if (!res.ok) throw VTD.errorFrom(res.status, await res.text());
    return res.text();
  }

  // ---------- axes ----------
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
  // The drawing is as wide as its box (at least 300 px of user units; the SVG then scales down to the box).
  const widthOf = (box) => Math.max(300, Math.round(box.clientWidth || 460));

  /** A line chart: series = [{pts: [[x, y]], color, label, dash}]; `equal` keeps metres square (top views). */
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
    const tx = ticks(x0, x1, W < 420 ? 4 : 6), ty = ticks(y0, y1, 5);
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

  /**
   * Horizontal bars: items = [{label, value, color?}]; `fmt` writes a value's label, `unit` names the axis.
   * Labels longer than the left margin are cut with an ellipsis (the full text is the bar's tooltip).
   */
  function barChart(box, items, { unit, fmt = (v) => num(v, v < 10 ? 2 : 1), ariaLabel = unit } = {}) {
    const W = widthOf(box);
    const rowH = 26, M = { l: Math.min(150, Math.round(W * 0.34)), r: 70, t: 6, b: 38 }, H = M.t + M.b + rowH * items.length;
    const max = Math.max(...items.map((i) => i.value), 1e-9), pw = W - M.l - M.r;
    const step = ticks(0, max, 4).step, top = Math.ceil(max / step - 1e-9) * step;
    const tx = ticks(0, top, 4);
    const X = (v) => M.l + v / top * pw;
    const svg = svgEl("svg", { viewBox: `0 0 ${W} ${H}`, role: "img", "aria-label": ariaLabel });
    const grid = svgEl("g", { class: "grid" }), axis = svgEl("g", { class: "axis" });
    for (const v of tx.values) {
      grid.append(svgEl("line", { x1: X(v), x2: X(v), y1: M.t, y2: H - M.b }));
      axis.append(svgEl("text", { x: X(v), y: H - M.b + 14, "text-anchor": "middle" }, tickText(v, tx.step)));
    }
    axis.append(svgEl("text", { x: M.l + pw / 2, y: H - 2, "text-anchor": "middle" }, unit));
    svg.append(grid, axis);
    const maxChars = Math.floor((M.l - 10) / 6.5);
    items.forEach(({ label, value, color }, k) => {
      const y = M.t + k * rowH;
      const text = label.length > maxChars ? label.slice(0, maxChars - 1) + "…" : label;
      svg.append(svgEl("text", { x: M.l - 8, y: y + rowH / 2 + 4, "text-anchor": "end" }, text));
      const bar = svgEl("rect", { x: M.l, y: y + 4, width: Math.max(1, X(value) - M.l), height: rowH - 8,
        fill: color || PRESET_COLORS.full, rx: 2, class: "bar" });
      bar.append(svgEl("title", {}, `${label}: ${fmt(value)}`));
      svg.append(bar, svgEl("text", { x: X(value) + 5, y: y + rowH / 2 + 4 }, fmt(value)));
    });
    box.replaceChildren(svg);
  }
  const note = (box, text) => box.replaceChildren(el("p", { class: "muted" }, text));

  return { PRESET_COLORS, presetColor, parseTum, parseCsv, artifactText, lineChart, barChart, note };
})();
