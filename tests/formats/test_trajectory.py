from pathlib import Path

import numpy as np
import pytest

from formats.errors import FormatError
from formats.trajectory import TumTrajectory, parse_tum_trajectory, read_tum_trajectory, write_tum_trajectory


def _random(n: int, seed: int = 0) -> TumTrajectory:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    return TumTrajectory(np.sort(rng.uniform(0, 100, n)), rng.normal(size=(n, 3)), q)


def test_round_trip_to_the_written_precision(tmp_path: Path):
    traj = _random(50)
    write_tum_trajectory(tmp_path / "t.txt", traj, header="test")
    back = read_tum_trajectory(tmp_path / "t.txt")
    assert (tmp_path / "t.txt").read_text().startswith("# test\n# timestamp tx ty tz qx qy qz qw\n")
    np.testing.assert_allclose(back.timestamps, traj.timestamps, atol=5e-7)
    np.testing.assert_allclose(back.positions, traj.positions, atol=5e-8)
    np.testing.assert_allclose(back.quaternions, traj.quaternions, atol=5e-8)
    assert not list(tmp_path.glob("*.part"))


def test_sorted_by_time_commas_allowed():
    traj = parse_tum_trajectory("2,1,2,3,0,0,0,1\n# c\n1 4 5 6 0 0 0 1\n")
    np.testing.assert_array_equal(traj.timestamps, [1.0, 2.0])
    np.testing.assert_array_equal(traj.positions[0], [4, 5, 6])


@pytest.mark.parametrize(("text", "message"), [
    ("1 2 3\n", "expected 8 values"),
    ("1 2 3 4 0 0 0 x\n", "not a number"),
    ("1 2 3 inf 0 0 0 1\n", "non-finite"),
    ("1 2 3 4 0 0 0 0\n", "not unit length"),
])
def test_malformed_lines(text, message):
    with pytest.raises(FormatError, match=message) as info:
        parse_tum_trajectory("# header\n" + text, "gt.txt")
    assert info.value.line == 2


def test_empty_text_parses_but_a_file_needs_poses(tmp_path: Path):
    assert len(parse_tum_trajectory("# nothing\n")) == 0
    (tmp_path / "t.txt").write_text("# nothing\n")
    with pytest.raises(FormatError, match="no poses"):
        read_tum_trajectory(tmp_path / "t.txt")
    with pytest.raises(FormatError, match="not found"):
        read_tum_trajectory(tmp_path / "missing.txt")
