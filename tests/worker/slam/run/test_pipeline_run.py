"""The run object: stepped by hand it gives what run_pipeline gives; one map and one sensor model for all parts."""
from __future__ import annotations

import numpy as np
import pytest

from tests.worker.slam.synthetic_room import trajectory, write_sequence
from worker.slam.camera import PRESETS, Camera
from worker.slam.io.sequence import Sequence
from worker.slam.pipeline import run_pipeline
from worker.slam.presets import get_preset
from worker.slam.run.metrics import run_metrics
from worker.slam.run.parts import build_slam
from worker.slam.run.pipeline_run import PipelineRun
from worker.slam.sensor import SensorModel

# metrics.json's run-level keys, in order (read by the repositories, the dashboard and the batch table)
RUN_KEYS = ["frames", "tracked", "lost", "relocalisations", "new_maps", "map_merges", "established_switches",
            "rescued_frames", "last_pose_retries", "frames_refit", "frames_smoothed", "keyframes", "map_points",
            "fused_observations", "loops", "loops_applied", "fps", "tracking_fps", "tracking_cpu_ms", "timings_ms",
            "overlapped_stages", "dense_points", "stage_info", "peak_rss_mb", "camera", "preset", "start",
            "tracked_fraction", "warnings", "smoothing_skipped", "version", "commit"]


@pytest.fixture(scope="module")
def room_seq(tmp_path_factory):
    return write_sequence(tmp_path_factory.mktemp("room"), trajectory(12, yaw_span_deg=10))


def test_stepping_by_hand_gives_what_run_pipeline_gives(room_seq):
    cfg = get_preset("orb-only")
    ref = run_pipeline(Sequence(room_seq), cfg, read_ahead=0, restore_behind=False)
    seq = Sequence(room_seq)
    first = seq[0]
    progress: list[tuple[int, int, str]] = []
    with PipelineRun(seq.camera, cfg, [], sequence=seq, total=len(seq),
                     progress=lambda d, t, s: progress.append((d, t, s))) as run:
        for frame in [first] + [seq[i] for i in range(1, len(seq))]:
            assert run.step(frame).ok
        res = run.finish()
    assert np.array_equal(res.trajectory.poses, ref.trajectory.poses)
    assert np.array_equal(res.keyframes.poses, ref.keyframes.poses)
    assert list(res.metrics) == list(ref.metrics) and list(res.metrics)[: len(RUN_KEYS)] == RUN_KEYS
    assert [r["frame_index"] for r in res.frame_stats] == list(range(len(seq)))
    assert progress[0] == (1, 12, "tracking") and progress[-1] == (12, 12, "evaluation")


def test_one_map_and_one_sensor_model_for_every_part():
    cfg = get_preset("orb-only", {"loop.enabled": True})
    parts = build_slam(PRESETS["bonn"], cfg)
    assert parts.closer is not None
    assert parts.tracker.map is parts.map and parts.mapper.map is parts.map and parts.closer.map is parts.map
    assert parts.tracker.sensor is parts.sensor
    for part in (parts.mapper, parts.closer):
        assert part.K is parts.sensor.K and part.bf == parts.sensor.bf and part.inv_sigma2 is parts.sensor.inv_sigma2


def test_sensor_model_is_read_only_and_matches_the_extractor():
    cfg = get_preset("orb-only")
    sensor = SensorModel.build(PRESETS["bonn"], cfg.features, cfg.tracking)
    extractor = build_slam(PRESETS["bonn"], cfg).tracker.extractor
    assert np.array_equal(sensor.scales, extractor.scales) and np.array_equal(sensor.inv_sigma2, extractor.inv_sigma2)
    assert sensor.scale_factor == pytest.approx(cfg.features.scale_factor)
    assert np.allclose(sensor.sigmas, sensor.scales)
    assert sensor.dist is not None and sensor.size == (640, 480)
    with pytest.raises(ValueError):
        sensor.K[0, 0] = 1.0
    assert SensorModel.build(Camera(500.0, 500.0, 320.0, 240.0), cfg.features, cfg.tracking).dist is None


def test_run_metrics_keys_in_order():
    cfg = get_preset("orb-only")
    with PipelineRun(PRESETS["tum3"], cfg, []) as run:
        run.timer.lap("tracking")
        m = run_metrics(run.log, run.parts, run.timer, loop_s=0.0, frames_refit=0, frames_smoothed=0,
                        smoothing_skipped=None, overlapped=set(),
                        dense_points=0, camera=PRESETS["tum3"], preset=cfg.name, start=0)
    assert list(m) == RUN_KEYS
