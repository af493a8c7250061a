"""RPE as TUM's evaluate_rpe.py computes it: golden tests on the three published TUM results (DATA.md).

Expected values come from `tum_rpe_reference.py`, a step-by-step re-implementation of the script (its reader,
binary-search lookup and 4x4 `ominus`, no pair sub-sampling), independent of the module under test; the
module must agree to 1e-6 relative in both modes, with the same number of pairs.
"""
import dataclasses
import json

import numpy as np
import pytest
from evo.core.metrics import RPE
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from cli.main import app
from tests.worker.slam.evaluation import tum_rpe_reference as tum
from worker.slam.evaluation.rpe import RpeMode, _errors, relative_pose_error
from worker.slam.evaluation.stats import error_stats
from worker.slam.io.trajectory import Trajectory, read_tum_trajectory

GOLDEN = [
    ("tum_fr3_walking_xyz", "dynaslam_estimate.txt"),
    ("tum_fr1_xyz", "rgbdslam_estimate.txt"),
    ("tum_fr2_desk", "orbslam2_estimate.txt"),
]


def _assert_stats_match(got, expected_errors):
    exp = error_stats(expected_errors)
    for field in ("rmse", "mean", "median", "std", "max"):
        assert getattr(got, field) == pytest.approx(getattr(exp, field), rel=1e-6, abs=1e-12), field


# fr2_desk in all-pairs mode (4.6 M pairs, ~10 s for the reference) is left out for time; the other two
# sequences cover that mode with 0.57 M and 0.62 M pairs.
CASES = [(f, e, RpeMode.FIXED_DELTA) for f, e in GOLDEN] + [(f, e, RpeMode.ALL_PAIRS) for f, e in GOLDEN[:2]]


@pytest.mark.parametrize("folder,estimate,mode", CASES)
def test_golden_rpe_matches_tum_script(shared, folder, estimate, mode):
    d = shared / "data" / "trajectories" / folder
    expected = tum.evaluate_rpe(tum.read_trajectory(d / "groundtruth.txt"), tum.read_trajectory(d / estimate),
                                fixed_delta=mode is RpeMode.FIXED_DELTA, delta=1.0)
    got = relative_pose_error(read_tum_trajectory(d / "groundtruth.txt"), read_tum_trajectory(d / estimate),
                              mode, 1.0)
    assert got is not None and got.pairs == len(expected.trans)
    _assert_stats_match(got.trans, expected.trans)
    _assert_stats_match(got.rot_deg, expected.rot_deg)


def test_golden_walking_xyz_fixed_delta_value(shared):
    """The 1 s figure of the DynaSLAM walking_xyz estimate as the script computes it. The previous
    implementation gave 0.0215 m (it kept pairs shorter than 1 s at the end of the trajectory and composed
    the error in evo's order); evo's order alone gives 0.0219 m."""
    d = shared / "data" / "trajectories" / "tum_fr3_walking_xyz"
    got = relative_pose_error(read_tum_trajectory(d / "groundtruth.txt"),
                              read_tum_trajectory(d / "dynaslam_estimate.txt"))
    assert got is not None and got.pairs == 728
    assert got.trans.rmse == pytest.approx(0.02181, abs=5e-6)


def test_golden_rpe_through_cli(shared):
    d = shared / "data" / "trajectories" / "tum_fr1_xyz"
    args = ["eval", str(d / "groundtruth.txt"), str(d / "rgbdslam_estimate.txt"), "--json"]
    default = json.loads(CliRunner().invoke(app, args).stdout)
    fixed = json.loads(CliRunner().invoke(app, [*args, "--rpe-mode", "fixed-delta"]).stdout)
    assert default["rpe"]["mode"] == "all-pairs" and default["rpe"]["delta_s"] is None
    assert fixed["rpe"]["mode"] == "fixed-delta" and fixed["rpe"]["delta_s"] == 1.0
    assert default["rpe"]["pairs"] > fixed["rpe"]["pairs"] > 0
    assert set(fixed["rpe"]["trans"]) == {"rmse", "mean", "median", "std", "max"}
    sampled = json.loads(CliRunner().invoke(app, [*args, "--rpe-max-pairs", "5000"]).stdout)
    assert sampled["rpe"]["max_pairs"] == 5000 and 0 < sampled["rpe"]["pairs"] <= 5000


def test_cli_rejects_unknown_rpe_mode(tmp_path):
    out = CliRunner().invoke(app, ["eval", str(tmp_path / "a.txt"), str(tmp_path / "b.txt"), "--rpe-mode", "x"])
    assert out.exit_code != 0 and "--rpe-mode" in out.output


def _poses(n, seed, step=0.02):
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, 3] = np.cumsum(rng.normal(0, step, (n, 3)), axis=0)
    poses[:, :3, :3] = Rotation.from_rotvec(np.cumsum(rng.normal(0, step, (n, 3)), axis=0)).as_matrix()
    return poses


def test_pair_errors_are_evos_relative_error_of_the_reversed_pair():
    """TUM's E on (i, j) is the inverse of evo's RPE matrix on (j, i): same translation norm and angle."""
    p, q = _poses(40, 1), _poses(40, 2)
    i, j = np.arange(0, 30), np.arange(10, 40)
    trans, rot = _errors(p, q, iter([(i, j)]))
    for k in range(len(i)):
        e = RPE.rpe_base(q[j[k]], q[i[k]], p[j[k]], p[i[k]])
        assert trans[k] == pytest.approx(np.linalg.norm(e[:3, 3]), rel=1e-9)
        angle = np.degrees(np.arccos(np.clip((np.trace(e[:3, :3]) - 1) / 2, -1, 1)))
        assert rot[k] == pytest.approx(angle, abs=1e-6)


def test_fixed_delta_drops_pairs_ending_on_the_last_pose():
    """31 poses at 10 Hz (3 s): i = 0..19 pair with i + 10; from i = 20 on the closest pose to t_i + 1 s is
    the last one, and the script drops those pairs (no shorter intervals at the end)."""
    t = np.arange(31) / 10.0
    gt = Trajectory(t, _poses(31, 3))
    est = Trajectory(t, _poses(31, 4))
    got = relative_pose_error(gt, est, RpeMode.FIXED_DELTA, 1.0)
    assert got is not None and got.pairs == 20


def test_all_pairs_counts_every_ordered_pair_with_ground_truth_nearby():
    t = np.arange(50) / 30.0
    gt = Trajectory(t, _poses(50, 5))
    est_t = t.copy()
    est_t[-1] += 0.5  # past the ground truth's end by 0.5 s: every pair with it is skipped
    est = Trajectory(est_t, _poses(50, 6))
    got = relative_pose_error(gt, est, RpeMode.ALL_PAIRS)
    assert got is not None and got.pairs == 49 * 49 and got.delta_s is None


def test_identical_trajectories_have_zero_rpe_in_both_modes():
    t = np.arange(90) / 30.0
    traj = Trajectory(t, _poses(90, 7))
    for mode in RpeMode:
        got = relative_pose_error(traj, traj, mode)
        assert got is not None and got.trans.max < 1e-12 and got.rot_deg.max < 1e-5


def test_too_short_for_a_pair_gives_none():
    t = np.arange(5) / 30.0  # 0.13 s: every pose's 1 s partner is the last pose
    traj = Trajectory(t, _poses(5, 8))
    assert relative_pose_error(traj, traj, RpeMode.FIXED_DELTA, 1.0) is None


def test_max_pairs_samples_reproducibly_and_close_to_every_pair(shared):
    """Sampling (the script's --max_pairs) evaluates at most that many pairs, the same ones each call, and
    its statistics estimate the exhaustive ones."""
    d = shared / "data" / "trajectories" / "tum_fr3_walking_xyz"
    gt, est = read_tum_trajectory(d / "groundtruth.txt"), read_tum_trajectory(d / "dynaslam_estimate.txt")
    full = relative_pose_error(gt, est, RpeMode.ALL_PAIRS)
    a = relative_pose_error(gt, est, RpeMode.ALL_PAIRS, max_pairs=20_000)
    b = relative_pose_error(gt, est, RpeMode.ALL_PAIRS, max_pairs=20_000)
    assert full is not None and a is not None and a == b
    assert 19_000 < a.pairs <= 20_000 and a.max_pairs == 20_000 and full.max_pairs == 0
    assert a.trans.rmse == pytest.approx(full.trans.rmse, rel=0.03)
    fixed = relative_pose_error(gt, est, RpeMode.FIXED_DELTA, 1.0, max_pairs=100)
    assert fixed is not None and fixed.pairs == 100


def test_max_pairs_above_the_pair_count_changes_nothing():
    t = np.arange(60) / 30.0
    gt, est = Trajectory(t, _poses(60, 9)), Trajectory(t, _poses(60, 10))
    for mode in RpeMode:
        every = relative_pose_error(gt, est, mode)
        assert every is not None
        assert relative_pose_error(gt, est, mode, max_pairs=10**6) == dataclasses.replace(every, max_pairs=10**6)
