"""metrics.json's run-level figures, in their fixed order (readers and the typed schema rely on the keys)."""
from __future__ import annotations

import resource

import numpy as np

from formats.version import provenance
from worker.slam.camera import Camera
from worker.slam.run.frame_log import FrameLog
from worker.slam.run.parts import SlamParts
from worker.slam.run.timer import StageTimer


def run_metrics(log: FrameLog, parts: SlamParts, timer: StageTimer, *, loop_s: float, frames_refit: int,
                frames_smoothed: int, smoothing_skipped: str | None, overlapped: set[str], dense_points: int,
                camera: Camera, preset: str, start: int) -> dict:
    """The 30 run-level entries of metrics.json, then the code's version and git commit (`formats.version`);
    the stages' summaries and the evaluation follow them.

    `loop_s`: wall time of the frame loop (s); `frames_refit`: frames re-solved against the final map;
    `frames_smoothed`: frames the end-of-run smoothing moved; `smoothing_skipped`: why it did not run (None: it
    ran); `overlapped`: stages whose work ran ahead on another thread; `dense_points`: points in map.ply."""
    tracked = np.array(log.tracked, dtype=bool)
    total = len(log)
    tracker, smap, closer = parts.tracker, parts.map, parts.closer
    return {
        "frames": total, "tracked": int(tracked.sum()), "lost": int((~tracked).sum()),
        "relocalisations": log.relocalisations, "new_maps": log.new_maps, "map_merges": log.merges,
        "established_switches": tracker.established_switches,
        "rescued_frames": tracker.rescued_frames, "last_pose_retries": tracker.last_pose_retries,
        "frames_refit": frames_refit, "frames_smoothed": frames_smoothed,
        "keyframes": len(smap), "map_points": smap.points.n_alive, "fused_observations": parts.mapper.fused,
        "loops": closer.n_loops if closer else 0, "loops_applied": closer.n_applied if closer else 0,
        "fps": round(total / loop_s, 2) if loop_s > 0 else None,
        "tracking_fps": round(1000.0 / np.mean(timer.ms["tracking"]), 2) if timer.ms["tracking"] else None,
        "tracking_cpu_ms": round(1000 * float(np.mean(log.cpu_tracking)), 3) if log.cpu_tracking else None,
        "timings_ms": timer.means(),
        "overlapped_stages": sorted(overlapped),
        "dense_points": dense_points,
        "stage_info": {k: round(float(np.mean(v)), 4) for k, v in log.stage_info.items()},
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "camera": camera.to_dict(), "preset": preset, "start": start,
        "tracked_fraction": round(float(tracked.mean()), 4) if total else None,
        "warnings": lost_warnings(tracked, start), "smoothing_skipped": smoothing_skipped,
        **provenance(),
    }


def smoothing_skipped(smooth_frames: bool, refit_ran: bool, keyframes: int) -> str | None:
    """Why the end-of-run frame smoothing does not run (it weighs each frame by its refit's information, so
    it needs `mapping.refit_frames` and a map), or None when it runs."""
    if not smooth_frames:
        return "mapping.smooth_frames is off"
    if not refit_ran:
        return "mapping.refit_frames is off (the smoothing weighs the frames by their refit)"
    return None if keyframes else "the map is empty"


def lost_warnings(tracked: np.ndarray, start: int) -> list[str]:
    """A warning when frames were not tracked: how many, where the longest lost stretch is, and that
    trajectory.txt (and the evaluation) hold only the tracked frames."""
    lost = np.flatnonzero(~tracked)
    if not len(lost):
        return []
    runs = np.split(lost, np.flatnonzero(np.diff(lost) > 1) + 1)  # consecutive lost frames
    longest = max(runs, key=len)
    return [f"{len(lost)} of {len(tracked)} frames ({100 * len(lost) / len(tracked):.1f} %) were not tracked "
            f"(longest stretch: frames {start + int(longest[0])}..{start + int(longest[-1])}); trajectory.txt "
            f"and the ATE/RPE hold only the {len(tracked) - len(lost)} tracked frames"]


def with_truth(stages: dict[str, dict], truth: dict[str, dict]) -> dict[str, dict]:
    """The stages' summaries (by stage name) each with its evaluation against truth (`truth_observer`) last, under
    "truth", where it has one."""
    return {name: {**summary, "truth": truth[name]} if name in truth else summary for name, summary in stages.items()}
