"""Figures of a trajectory for people who look rather than read: PNGs with the names of `formats.artifacts`.

The top view and x/y/z over time (the estimate against the aligned ground truth when there is one), the absolute
trajectory error per pose over time and the mean time per stage. matplotlib draws them on its Agg canvas
(no display, no pyplot state, safe in a worker thread); it is imported when a figure is drawn, never at import
time, so nothing that merely imports the pipeline pays for it.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from formats import artifacts
from worker.slam.io.trajectory import Trajectory

if TYPE_CHECKING:
    from matplotlib.figure import Figure

DPI = 100
ESTIMATE = "#1f6fd1"
TRUTH = "#6b6b6b"
ERROR = "#d1451f"


def write_figures(out: Path, estimate: Trajectory, groundtruth: Trajectory | None = None,
                  errors: tuple[np.ndarray, np.ndarray] | None = None,
                  timings_ms: Mapping[str, object] | None = None, title: str = "") -> list[Path]:
    """Draw into ``out`` the figures the inputs allow; returns the files written.

    ``groundtruth``: the ground truth already aligned onto the estimate (same world frame). ``errors``:
    (timestamps, translation error in metres) per matched pose. ``timings_ms``: mean ms per stage (non-numbers
    are skipped). Times on the plots are seconds since the estimate's first pose. An estimate of under two poses
    draws no trajectory figures.
    """
    out.mkdir(parents=True, exist_ok=True)
    gt = groundtruth if groundtruth is not None and len(groundtruth) else None
    t0 = float(estimate.timestamps[0]) if len(estimate) else 0.0
    written: list[Path] = []
    if len(estimate) >= 2:
        written.append(_save(_top_view(estimate, gt, title), out / artifacts.PLOT_TRAJECTORY_TOP))
        written.append(_save(_xyz(estimate, gt, t0, title), out / artifacts.PLOT_XYZ))
    if errors is not None:
        ts, err = (np.asarray(a, dtype=float) for a in errors)
        keep = np.isfinite(ts) & np.isfinite(err)
        if keep.sum() >= 1:
            written.append(_save(_ate(ts[keep] - t0, err[keep], title), out / artifacts.PLOT_ATE_ERROR))
    stages = [(str(k), float(v)) for k, v in (timings_ms or {}).items()
              if isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v)]
    if stages:
        written.append(_save(_timings(stages, title), out / artifacts.PLOT_TIMINGS))
    return written


def _figure(width: float, height: float, *, left: float = 0.7, right: float = 0.15, bottom: float = 0.5,
            top: float = 0.35) -> Figure:
    """A figure of ``width`` x ``height`` inches with fixed margins in inches (an automatic layout engine would
    cost more than the drawing)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height, top=1 - top / height)
    return fig


def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, format="png", dpi=DPI, pil_kwargs={"compress_level": 1})  # speed over bytes
    return path


def _titled(text: str, title: str) -> str:
    return f"{title}: {text}" if title else text


def _top_view(est: Trajectory, gt: Trajectory | None, title: str) -> Figure:
    """The x-z plane (TUM camera convention: y points down, so x-z is the floor seen from above)."""
    fig = _figure(5.5, 5.0, left=0.85)
    ax = fig.add_subplot()
    p = est.positions
    ax.plot(p[:, 0], p[:, 2], color=ESTIMATE, lw=1.6, label="estimate")
    if gt is not None:  # drawn over the estimate, thin and dashed, so both show where they agree
        ax.plot(gt.positions[:, 0], gt.positions[:, 2], "--", color=TRUTH, lw=1.1, label="ground truth (aligned)")
    ax.plot(p[0, 0], p[0, 2], "o", color="#2e9e44", ms=7, label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(_titled("trajectory, top view (x-z)", title), fontsize=10)
    return fig


def _xyz(est: Trajectory, gt: Trajectory | None, t0: float, title: str) -> Figure:
    fig = _figure(7.0, 5.5)
    axes = fig.subplots(3, 1, sharex=True, gridspec_kw={"hspace": 0.12})
    for i, (ax, name) in enumerate(zip(axes, "xyz", strict=True)):
        ax.plot(est.timestamps - t0, est.positions[:, i], color=ESTIMATE, lw=1.6, label="estimate")
        if gt is not None:
            ax.plot(gt.timestamps - t0, gt.positions[:, i], "--", color=TRUTH, lw=1.1, label="ground truth (aligned)")
        ax.set_ylabel(f"{name} (m)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time since first pose (s)")
    axes[0].set_title(_titled("position over time", title), fontsize=10)
    return fig


def _ate(t: np.ndarray, err: np.ndarray, title: str) -> Figure:
    mm = float(err.max()) < 0.1  # small errors read better in millimetres
    k, unit = (1000.0, "mm") if mm else (1.0, "m")
    rmse = float(np.sqrt(np.mean(err ** 2)))
    fig = _figure(7.0, 3.2)
    ax = fig.add_subplot()
    ax.plot(t, err * k, color=ERROR, lw=1.3, marker="." if len(t) < 60 else None, label="error per pose")
    ax.axhline(rmse * k, color=TRUTH, ls="--", lw=1.0, label=f"RMSE {rmse * k:.3g} {unit}")
    ax.set_ylim(bottom=0)
    ax.set_xlabel("time since first pose (s)")
    ax.set_ylabel(f"ATE ({unit})")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(_titled("absolute trajectory error (SE(3)-aligned)", title), fontsize=10)
    return fig


def _timings(stages: list[tuple[str, float]], title: str) -> Figure:
    names = [n.replace("_", " ") for n, _ in stages]
    fig = _figure(7.0, 1.0 + 0.26 * len(stages), left=0.25 + 0.06 * max(len(n) for n in names))
    ax = fig.add_subplot()
    values = [v for _, v in stages]
    y = np.arange(len(stages))
    ax.barh(y, values, color=ESTIMATE, height=0.6)
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()  # in the order the run recorded them, first on top
    for yi, v in zip(y, values, strict=True):
        ax.annotate(f"{v:.3g}", (v, yi), xytext=(3, 0), textcoords="offset points", va="center", fontsize=7)
    ax.set_xlabel("mean time per call (ms)")
    ax.margins(x=0.12)
    ax.grid(axis="x", alpha=0.3)
    ax.set_title(_titled("time per stage", title), fontsize=10)
    return fig
