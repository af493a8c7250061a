"""Golden tests: reproduce the published ATE of three real TUM results (DATA.md), plus synthetic checks."""
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from cli.main import app
from worker.slam.errors import EvaluationError, TrajectoryFormatError
from worker.slam.evaluation.metrics import evaluate
from worker.slam.io.trajectory import Trajectory, read_tum_trajectory, write_tum_trajectory

GOLDEN = [  # folder, estimate, ATE RMSE, matched poses
    ("tum_fr3_walking_xyz", "dynaslam_estimate.txt", 0.0163, 757),
    ("tum_fr1_xyz", "rgbdslam_estimate.txt", 0.0135, 786),
    ("tum_fr2_desk", "orbslam2_estimate.txt", 0.0081, 2225),
]


@pytest.mark.parametrize("folder,estimate,rmse,matched", GOLDEN)
def test_golden_ate(shared, folder, estimate, rmse, matched):
    d = shared / "data" / "trajectories" / folder
    result = evaluate(read_tum_trajectory(d / "groundtruth.txt"), read_tum_trajectory(d / estimate))
    assert result.matched == matched
    assert abs(result.ate.rmse - rmse) <= 0.0001
    assert result.rpe is not None and result.rpe.trans.rmse > 0 and result.rpe.delta_s == 1.0


@pytest.mark.parametrize("folder,estimate,rmse,matched", GOLDEN)
def test_golden_ate_through_cli(shared, folder, estimate, rmse, matched):
    d = shared / "data" / "trajectories" / folder
    out = CliRunner().invoke(app, ["eval", str(d / "groundtruth.txt"), str(d / estimate), "--json"])
    assert out.exit_code == 0, out.output
    data = json.loads(out.stdout)  # stderr may carry log lines; the JSON is on stdout alone
    assert abs(data["ate"]["rmse"] - rmse) <= 0.0001 and data["matched_poses"] == matched
    assert set(data["ate"]) == {"rmse", "mean", "median", "std", "max"}


def _random_walk(n=200, seed=0):
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, 3] = np.cumsum(rng.normal(0, 0.01, (n, 3)), axis=0)
    poses[:, :3, :3] = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.01, (n, 3)), axis=0)).as_matrix()
    return Trajectory(np.arange(n) / 30.0, poses)


def test_rigidly_moved_copy_has_zero_ate():
    gt = _random_walk()
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [10, 20, 30], degrees=True).as_matrix()
    T[:3, 3] = [1, 2, 3]
    r = evaluate(gt, Trajectory(gt.timestamps, T @ gt.poses))
    assert r.rpe is not None
    # TUM's angle is arccos((tr R - 1) / 2), which cannot resolve much below 1e-8 rad (~1e-6 deg)
    assert r.ate.rmse < 1e-9 and r.rpe.trans.rmse < 1e-9 and r.rpe.rot_deg.rmse < 1e-5


def test_known_offset_error():
    gt = _random_walk()
    est = gt.poses.copy()
    est[::2, 0, 3] += 0.01  # alternating 1 cm: after alignment errors are ~5 mm
    r = evaluate(gt, Trajectory(gt.timestamps, est))
    assert r.ate.rmse == pytest.approx(0.005, rel=0.05)


def test_scale_is_not_corrected():
    gt = _random_walk()
    est = gt.poses.copy()
    est[:, :3, 3] *= 2
    assert evaluate(gt, Trajectory(gt.timestamps, est)).ate.rmse > 0.01


def test_no_overlap_is_an_error():
    gt = _random_walk()
    with pytest.raises(EvaluationError):
        evaluate(gt, Trajectory(gt.timestamps + 1000, gt.poses))


def test_an_estimate_that_never_moved_is_an_evaluation_error():
    """A lost tracker repeats one pose: the rigid alignment is undefined, which must be a domain error that
    says so (the pipeline keeps the run's outputs on EvaluationError), not evo's GeometryException."""
    gt = _random_walk()
    frozen = Trajectory(gt.timestamps, np.tile(np.eye(4), (len(gt), 1, 1)))
    with pytest.raises(EvaluationError, match="never moved") as info:
        evaluate(gt, frozen)
    assert info.value.detail == {"reason": "degenerate_alignment"}


def test_cli_degenerate_estimate_is_bad_input(tmp_path, capsys):
    import sys

    from cli.errors import run_with_error_mapping
    gt = _random_walk()
    write_tum_trajectory(tmp_path / "gt.txt", gt)
    write_tum_trajectory(tmp_path / "est.txt", Trajectory(gt.timestamps, np.tile(np.eye(4), (len(gt), 1, 1))))
    old = sys.argv
    sys.argv = ["vtdslam", "eval", str(tmp_path / "gt.txt"), str(tmp_path / "est.txt")]
    try:
        assert run_with_error_mapping(app) == 2
    finally:
        sys.argv = old
    assert "alignment is undefined" in capsys.readouterr().err


def test_roundtrip(tmp_path):
    gt = _random_walk()
    write_tum_trajectory(tmp_path / "t.txt", gt)
    back = read_tum_trajectory(tmp_path / "t.txt")
    assert np.allclose(back.poses, gt.poses, atol=1e-6) and np.allclose(back.timestamps, gt.timestamps, atol=1e-6)


def test_bad_trajectory_line(tmp_path):
    (tmp_path / "t.txt").write_text("# x\n0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n")
    with pytest.raises(TrajectoryFormatError, match=r"t.txt:3"):
        read_tum_trajectory(tmp_path / "t.txt")


def test_cli_bad_input_exit_code(tmp_path, capsys):
    import sys

    from cli.errors import run_with_error_mapping
    (tmp_path / "t.txt").write_text("garbage\n")
    old = sys.argv
    sys.argv = ["vtdslam", "eval", str(tmp_path / "t.txt"), str(tmp_path / "t.txt")]
    try:
        assert run_with_error_mapping(app) == 2
    finally:
        sys.argv = old
    assert "t.txt:1" in capsys.readouterr().err


def test_aligned_groundtruth_lies_on_the_estimate():
    gt = _random_walk()
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", 40, degrees=True).as_matrix()
    T[:3, 3] = [3, -1, 2]
    est = Trajectory(gt.timestamps, T @ gt.poses)
    r = evaluate(gt, est)
    assert np.allclose(r.aligned_groundtruth.poses, est.poses, atol=1e-6)
