"""The pipeline runner: outputs, metrics, config snapshot, stage hooks, progress and cancellation; real data."""
from __future__ import annotations

import dataclasses
import json
import logging

import numpy as np
import pytest

from formats.catalog import PipelinePreset, StageContract
from formats.ply import read_ply
from formats.version import PROVENANCE_KEYS, provenance
from tests.worker.slam.synthetic_room import pose, trajectory, write_sequence
from worker.slam.camera import PRESETS
from worker.slam.catalog import Catalog, CatalogStage, shipped_catalog
from worker.slam.config import PipelineConfig
from worker.slam.errors import ConfigError
from worker.slam.io.sequence import Frame, Sequence
from worker.slam.io.trajectory import read_tum_trajectory
from worker.slam.pipeline import PipelineCancelled, run_pipeline
from worker.slam.presets import get_preset, preset_names
from worker.slam.stages import FrameInputs, StageContext


@pytest.fixture(scope="module")
def room_seq(tmp_path_factory):
    return write_sequence(tmp_path_factory.mktemp("room"), trajectory(40, yaw_span_deg=30))


def test_run_writes_all_outputs_and_tracks_to_subcentimetre(room_seq, tmp_path):
    calls = []
    res = run_pipeline(Sequence(room_seq), get_preset("orb-only"), tmp_path,
                       progress=lambda d, t, s: calls.append((d, t, s)))
    for name in ("trajectory.txt", "keyframes.txt", "map.ply", "metrics.json", "config.json"):
        assert (tmp_path / name).is_file(), name
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["frames"] == 40 and m["tracked"] == 40 and m["lost"] == 0
    assert m["ate"]["rmse"] < 0.01 and set(m["ate"]) == {"rmse", "mean", "median", "std", "max"}
    assert "rpe" in m and m["fps"] > 0 and "tracking" in m["timings_ms"] and m["peak_rss_mb"] > 0
    assert len(read_tum_trajectory(tmp_path / "trajectory.txt")) == 40
    xyz, rgb = read_ply(tmp_path / "map.ply")
    assert len(xyz) == m["dense_points"] > 1000
    snapshot = json.loads((tmp_path / "config.json").read_text())
    cfg = shipped_catalog().config_from_dict(snapshot)  # the code's version and commit are skipped
    assert cfg.to_dict() == get_preset("orb-only").to_dict()
    assert {k: snapshot[k] for k in PROVENANCE_KEYS} == {k: m[k] for k in PROVENANCE_KEYS} == provenance()
    assert calls[0] == (1, 40, "tracking") and calls[-1][2] == "writing"
    assert res.tracked.all()


def test_start_and_max_frames(room_seq):
    res = run_pipeline(Sequence(room_seq), get_preset("orb-only", {"dense.enabled": False}), start=10, max_frames=8)
    assert res.metrics["frames"] == 8 and np.isclose(res.trajectory.timestamps[0], 10 / 30)
    with pytest.raises(ConfigError):
        run_pipeline(Sequence(room_seq), get_preset("orb-only"), start=1000)


def test_cancellation_stops_the_run(room_seq):
    seen = []
    with pytest.raises(PipelineCancelled):
        run_pipeline(Sequence(room_seq), get_preset("orb-only"),
                     progress=lambda d, t, s: seen.append(d), should_cancel=lambda: len(seen) >= 3)
    assert len(seen) == 3


class _MaskLeftHalf:
    """A stand-in dynamic stage: excludes the left half of every frame and reports it."""

    name = "mask_left"

    def process(self, frame: Frame, inputs: FrameInputs, ctx: StageContext) -> FrameInputs:
        mask = np.zeros(frame.depth.shape, bool)
        mask[:, : frame.depth.shape[1] // 2] = True
        inputs.exclude_mask = mask
        inputs.info["masked_px"] = int(mask.sum())
        if ctx.last is not None:  # the last tracked pose, predicted from since
            assert ctx.last.covariance is None or ctx.last.covariance.shape == (6, 6)
            assert ctx.T_WC_pred is not None and ctx.T_WC_pred.shape == (4, 4)
            assert ctx.last.index < frame.index
        else:
            assert frame.index == 0
        return inputs


def _catalog_with(**extra) -> Catalog:
    """The shipped catalog plus a test's own sections, stages or presets (no shared state to undo)."""
    base = shipped_catalog()
    return dataclasses.replace(base, **{k: {**getattr(base, k), **v} for k, v in extra.items()})


def test_a_catalog_stage_and_preset_plug_in(room_seq):
    contract = StageContract("mask_left", provides=("exclude_mask",))
    catalog = _catalog_with(stages={"mask_left": CatalogStage(contract, lambda cfg, cam: _MaskLeftHalf())},
                            presets={"test-masked": PipelinePreset("test-masked", "test only", ("mask_left",))})
    assert "test-masked" in catalog.preset_names() and "test-masked" not in preset_names()
    seq = Sequence(room_seq)
    cfg = catalog.preset("test-masked", {"dense.stride": 8})
    res = run_pipeline(seq, cfg, max_frames=12, stages=catalog.build_stages(cfg, seq.camera))
    assert res.metrics["tracked"] == 12 and "mask_left" in res.metrics["timings_ms"]
    assert res.metrics["stage_info"] == {"masked_px": 320 * 480}
    for kf in res.slam_map.keyframes:  # masked pixels stay out of features and the dense map
        assert kf.feats.uv[:, 0].min() >= 319 and not kf.depth_small[:, :40].any()
    with pytest.raises(ConfigError):
        run_pipeline(Sequence(room_seq), PipelineConfig(stages=["no-such-stage"]), max_frames=2)


def test_config_snapshot_overrides_and_sections():
    from dataclasses import dataclass

    @dataclass
    class DemoSection:
        threshold: float = 1.0
        """A demo field."""

    catalog = _catalog_with(sections={"demo_section": DemoSection})
    cfg = catalog.preset("orb-only", {"tracking.ratio": 0.8, "demo_section": {"threshold": 2}})
    assert cfg.tracking.ratio == 0.8 and cfg.section("demo_section").threshold == 2.0
    d = cfg.to_dict()
    assert d["demo_section"] == {"threshold": 2.0} and d["name"] == "orb-only"
    assert catalog.config_from_dict(d).to_dict() == d
    assert list(d)[-4:] == ["segmentation", "culling", "restoration", "demo_section"]
    with pytest.raises(ConfigError, match="unknown config section 'demo_section'"):
        shipped_catalog().config_from_dict(d)  # a catalog without the section refuses it, whatever was imported
    with pytest.raises(ConfigError):
        cfg.with_overrides({"tracking.no_such_field": 1})
    with pytest.raises(ConfigError):
        cfg.with_overrides({"tracking": {"min_matches": "many"}})
    with pytest.raises(ConfigError):
        get_preset("no-such-preset")


@pytest.mark.realdata
def test_redkitchen_slice_tracks_accurately(redkitchen, tmp_path):
    res = run_pipeline(Sequence(redkitchen, PRESETS["7scenes"]), get_preset("orb-only"), tmp_path, max_frames=90)
    m = res.metrics
    assert m["lost"] == 0 and m["tracked"] == 90
    assert m["ate"]["rmse"] < 0.03
    assert m["dense_points"] > 10_000


def test_frames_are_refit_against_the_final_map_and_keyframes_keep_their_poses(room_seq, caplog):
    caplog.set_level(logging.INFO, logger="worker.slam.run.pipeline_run")
    off = run_pipeline(Sequence(room_seq), get_preset("orb-only", {"dense.enabled": False,
                                                                    "mapping.refit_frames": False}))
    on = run_pipeline(Sequence(room_seq), get_preset("orb-only", {"dense.enabled": False,
                                                                   "mapping.smooth_frames": False}))
    n_kf = on.metrics["keyframes"]
    assert off.metrics["frames_refit"] == 0
    # no refit, no smoothing (it weighs the frames by their refit): recorded and logged, as is turning it off
    assert off.metrics["frames_smoothed"] == 0 and "mapping.refit_frames is off" in off.metrics["smoothing_skipped"]
    assert (on.metrics["frames_smoothed"], on.metrics["smoothing_skipped"]) == (0, "mapping.smooth_frames is off")
    skips = [r.getMessage() for r in caplog.records if r.getMessage().startswith("frame smoothing skipped")]
    assert len(skips) == 2 and "mapping.refit_frames is off" in skips[0]
    assert 0 < on.metrics["frames_refit"] <= 40 - n_kf and "frame_refit" in on.metrics["timings_ms"]
    assert np.array_equal(on.keyframes.poses, off.keyframes.poses)
    moved = np.abs(on.trajectory.poses - off.trajectory.poses).max(axis=(1, 2)) > 0
    assert moved.sum() == on.metrics["frames_refit"]
    assert on.metrics["ate"]["rmse"] < 0.01  # the room of the first test: subcentimetre either way


@pytest.fixture(scope="module")
def handheld_seq(tmp_path_factory):
    """The room walked through at a hand-held pace (0.2 m/s, a wobble of 2 cm), not the circle of `room_seq`
    at 1.4 m/s and 6.7 m/s^2, which no constant-velocity prior fits."""
    s = np.linspace(0, 1, 40)
    poses = np.stack([pose([0.25 * si, 0.02 * np.sin(2 * np.pi * si), 0.05 * si], 8 * si,
                           -15 + 2 * np.sin(2 * np.pi * si)) for si in s])
    return write_sequence(tmp_path_factory.mktemp("handheld"), poses)


def test_smoothing_moves_frames_and_keyframes_and_lowers_the_frame_to_frame_error(handheld_seq):
    """The room's truth is exact, so its frame-to-frame RPE is the jitter the smoother exists to remove."""
    cfg = {"dense.enabled": False}
    plain = run_pipeline(Sequence(handheld_seq), get_preset("orb-only", {**cfg, "mapping.smooth_frames": False}))
    smooth = run_pipeline(Sequence(handheld_seq), get_preset("orb-only", cfg))
    assert "frame_smoothing" in smooth.metrics["timings_ms"] and "frame_smoothing" not in plain.metrics["timings_ms"]
    moved = np.abs(smooth.trajectory.poses - plain.trajectory.poses).max(axis=(1, 2)) > 0
    assert moved.sum() > 0.9 * len(moved)  # keyframes' frame poses too, not only the refitted frames
    assert smooth.metrics["frames_smoothed"] == moved.sum() and smooth.metrics["smoothing_skipped"] is None
    assert np.array_equal(smooth.keyframes.poses, plain.keyframes.poses)  # the map is left as BA made it
    rpe = lambda r: r.metrics["rpe_frame"]["trans"]["rmse"]  # noqa: E731
    assert rpe(smooth) < 0.5 * rpe(plain)  # seen: 3.1 -> 0.4 mm
    assert smooth.metrics["ate"]["rmse"] < plain.metrics["ate"]["rmse"]  # seen: 2.1 -> 1.0 mm


def test_a_marker_ground_truth_is_scored_against_the_camera(room_seq, tmp_path):
    """The room sequence with its truth given as Bonn marker poses (camera.json says `bonn-marker`): RPE and the
    corrected ATE match the camera's truth as closely as a camera ground truth does; ATE is also reported raw."""
    import shutil

    from worker.slam.io.bonn import T_ROS, marker_to_camera
    from worker.slam.io.trajectory import Trajectory, write_tum_trajectory

    seq = tmp_path / "marker"
    shutil.copytree(room_seq, seq)
    cam = read_tum_trajectory(seq / "groundtruth.txt")
    raw = T_ROS @ cam.poses @ np.linalg.inv(T_ROS @ marker_to_camera())
    write_tum_trajectory(seq / "groundtruth.txt", Trajectory(cam.timestamps, raw))
    spec = json.loads((seq / "camera.json").read_text())
    (seq / "camera.json").write_text(json.dumps({**spec, "groundtruth_frame": "bonn-marker"}))
    cfg = get_preset("orb-only", {"dense.enabled": False})
    m = run_pipeline(Sequence(seq), cfg).metrics
    ref = run_pipeline(Sequence(room_seq), cfg).metrics
    assert m["groundtruth_frame"] == "bonn-marker" and m["rpe_against"] == "camera (corrected from bonn-marker)"
    assert ref["groundtruth_frame"] == ref["rpe_against"] == "camera" and ref["ate_corrected"] == ref["ate"]
    for key in ("rpe", "rpe_frame"):
        assert m[key]["trans"]["rmse"] == pytest.approx(ref[key]["trans"]["rmse"], abs=1e-6), key
    assert m["ate_corrected"]["rmse"] == pytest.approx(ref["ate"]["rmse"], abs=1e-6)
    assert m["ate"]["rmse"] != pytest.approx(ref["ate"]["rmse"], abs=1e-6)  # the marker's path, published way
