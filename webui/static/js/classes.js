/* Segmentation classes on the job page: the legend (formats.class_palette colours, from metrics.json's
   segmentation.legend or partial.json's frame_legend), each class's share of the frames, and per-class recall
   against truth (augmented sequences with movers of several classes). */
"use strict";
window.VTDClasses = (() => {
  const { el, isNum } = VTD;
  const COLOUR = /^#[0-9a-f]{6}$/i;
  const pct = (x) => (isNum(x) ? (100 * x).toFixed(x < 0.001 ? 3 : 1) + " %" : "—");

  /** Legend entries that are well formed ({name, colour #rrggbb, dynamic}). */
  const entries = (legend) => (Array.isArray(legend) ? legend : [])
    .filter((e) => e && typeof e.name === "string" && typeof e.colour === "string" && COLOUR.test(e.colour));

  /** A row of swatches: each class in its colour, the ones that are not masked marked so. */
  function legend(list) {
    return el("ul", { class: "legend", "aria-label": "segmentation classes and their colours" },
      ...entries(list).map((e) => el("li", {}, el("span", { class: "swatch", style: `background:${e.colour}` }),
        e.name + (e.dynamic ? "" : " (not masked)"))));
  }

  /** Table of each class's mean share of the frames: potentially dynamic classes, then the others seen. */
  function shareTable(seg) {
    const rows = [];
    for (const [key, kind] of [["class_share", "potentially dynamic"], ["other_class_share", "seen, not masked"]]) {
      for (const [name, v] of Object.entries(seg[key] || {})) if (isNum(v)) rows.push([name, v, kind]);
    }
    if (!rows.length) return null;
    return el("table", { class: "data", id: "class-share" },
      el("thead", {}, el("tr", {}, el("th", {}, "Class"), el("th", { class: "n" }, "Share of the frame (mean)"), el("th", {}, ""))),
      el("tbody", {}, ...rows.map(([name, v, kind]) => el("tr", {}, el("td", {}, name), el("td", { class: "n" }, pct(v)),
        el("td", { class: "muted small" }, kind)))));
  }

  /** A class name, after a swatch of its colour when the run's legend has it. */
  function named(name, list) {
    const e = entries(list).find((x) => x.name === name);
    return e ? [el("span", { class: "swatch", style: `background:${e.colour}` }), name] : [name];
  }

  /** Per true mover class: share of its pixels segmentation marked and culling judged moving. */
  function recallTable(m) {
    const marked = (((m.segmentation || {}).truth || {}).recall_by_class) || {};
    const culled = (((m.culling || {}).truth || {}).mask_recall_by_class) || {};
    const names = [...new Set([...Object.keys(marked), ...Object.keys(culled)])].sort();
    if (!names.length) return null;
    const cell = (o) => el("td", { class: "n" }, o && isNum(o.recall) ? pct(o.recall) : "—");
    return el("table", { class: "data", id: "truth-by-class" },
      el("thead", {}, el("tr", {}, el("th", {}, "True mover class"), el("th", { class: "n" }, "Marked by segmentation"),
        el("th", { class: "n" }, "Judged moving by culling"), el("th", { class: "n" }, "Pixels"))),
      el("tbody", {}, ...names.map((n) => el("tr", {},
        el("td", { class: "legend-name" }, ...named(n, (m.segmentation || {}).legend)), cell(marked[n]), cell(culled[n]),
        el("td", { class: "n" }, String((marked[n] || culled[n] || {}).pixels ?? "—"))))));
  }

  return { legend, entries, shareTable, recallTable };
})();
