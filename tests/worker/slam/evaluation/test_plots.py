"""The figures: a run writes them beside its trajectory, a figure that cannot be drawn never fails the run, and
the plotting module draws what its inputs allow."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from formats import artifacts
from tests.worker.slam.synthetic_room import trajectory, write_sequence
from worker.slam.evaluation import plots
from worker.slam.io.sequence import Sequence
from worker.slam.io.trajectory import Trajectory
from worker.slam.pipeline import run_pipeline
from worker.slam.presets import get_preset

PNG = b"\x89PNG\r\n\x1a\n"


def assert_png(path: Path) -> None:
    data = path.read_bytes()
    assert data[:8] == PNG, path
    assert len(data) > 5000, (path, len(data))  # axes, lines and labels, not an empty canvas


@pytest.fixture(scope="module")
def room_seq(tmp_path_factory):
    return write_sequence(tmp_path_factory.mktemp("room"), trajectory(12, yaw_span_deg=10))


def _config():
    return get_preset("orb-only", {"dense.enabled": False})


def test_a_run_writes_its_figures(room_seq, tmp_path):
    run_pipeline(Sequence(room_seq), _config(), tmp_path)
    for name in artifacts.FIGURES:
        assert_png(tmp_path / name)
    assert not any("figures" in w for w in json.loads((tmp_path / artifacts.METRICS).read_text())["warnings"])


def test_a_figure_that_cannot_be_drawn_never_fails_the_run(room_seq, tmp_path, monkeypatch, caplog):
    def broken(*args, **kwargs):
        raise RuntimeError("no fonts today")

    monkeypatch.setattr("worker.slam.run.outputs.write_figures", broken)
    res = run_pipeline(Sequence(room_seq), _config(), tmp_path)
    assert res.tracked.all()
    for name in artifacts.PIPELINE_OUTPUTS:
        assert (tmp_path / name).is_file(), name
    assert not any((tmp_path / name).exists() for name in artifacts.FIGURES)
    warnings = json.loads((tmp_path / artifacts.METRICS).read_text())["warnings"]
    assert "figures not drawn: RuntimeError: no fonts today" in warnings
    assert "figures not drawn" in caplog.text


def _line(n: int) -> Trajectory:
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.linspace(0, 1, n)
    poses[:, 2, 3] = np.sin(np.linspace(0, 3, n))
    return Trajectory(np.arange(n) / 30.0, poses)


def test_only_the_figures_the_inputs_allow(tmp_path):
    est = _line(20)
    written = plots.write_figures(tmp_path, est, timings_ms={"tracking": 3.2, "dense": 1.5, "note": "x", "b": True})
    assert [p.name for p in written] == [artifacts.PLOT_TRAJECTORY_TOP, artifacts.PLOT_XYZ, artifacts.PLOT_TIMINGS]
    for p in written:
        assert_png(p)
    assert plots.write_figures(tmp_path / "one", _line(1)) == []  # one pose: no trajectory to draw
    errors = (est.timestamps, np.full(20, np.nan))  # no finite error: no error figure
    assert artifacts.PLOT_ATE_ERROR not in [p.name for p in plots.write_figures(tmp_path / "nan", est, est, errors)]
