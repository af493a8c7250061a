"""`vtdslam run` end to end on a rendered sequence, and its errors."""
from __future__ import annotations

import json

from typer.testing import CliRunner

from cli.main import app
from tests.worker.slam.synthetic_room import trajectory, write_sequence
from worker.slam.errors import CameraError, ConfigError


def test_run_command_writes_outputs(tmp_path):
    seq = write_sequence(tmp_path / "room", trajectory(16, yaw_span_deg=10))
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", str(seq), "--out", str(out), "--preset", "orb-only", "--start", "2",
                                   "--max-frames", "12", "--config", '{"dense.stride": 8}'])
    assert res.exit_code == 0, res.output
    assert "tracked 12" in res.output and "ATE rmse" in res.output
    m = json.loads((out / "metrics.json").read_text())
    assert m["frames"] == 12 and m["start"] == 2 and m["lost"] == 0
    assert json.loads((out / "config.json").read_text())["dense"]["stride"] == 8
    for name in ("trajectory.txt", "keyframes.txt", "map.ply"):
        assert (out / name).stat().st_size > 0


def test_run_command_errors(tmp_path):
    seq = write_sequence(tmp_path / "room", trajectory(2))
    (seq / "camera.json").unlink()
    res = CliRunner().invoke(app, ["run", str(seq), "--out", str(tmp_path / "o")])
    assert res.exit_code != 0 and isinstance(res.exception, CameraError)  # no camera anywhere
    res = CliRunner().invoke(app, ["run", str(seq), "--camera", "tum3", "--out", str(tmp_path / "o"),
                                   "--preset", "nope"])
    assert res.exit_code != 0 and isinstance(res.exception, ConfigError)
    res = CliRunner().invoke(app, ["run", str(seq), "--camera", "tum3", "--out", str(tmp_path / "o"),
                                   "--config", "{not json"])
    assert res.exit_code != 0 and isinstance(res.exception, ConfigError)


def test_run_refuses_intrinsics_the_api_refuses(tmp_path):
    """`--camera '{...}'` goes through formats.camera_spec like an upload: a principal point outside the image
    and an implausible focal length are refused before any frame is read."""
    seq = write_sequence(tmp_path / "room", trajectory(2))
    for spec, words in (('{"fx": 500, "fy": 500, "cx": 900, "cy": 240}', "cx must lie inside the image"),
                        ('{"fx": 5, "fy": 500, "cx": 320, "cy": 240}', "fx must be within 50..5000")):
        (seq / "camera.json").unlink(missing_ok=True)
        res = CliRunner().invoke(app, ["run", str(seq), "--camera", spec, "--out", str(tmp_path / "o")])
        assert isinstance(res.exception, CameraError) and words in res.exception.message


def test_the_cli_maps_every_error_of_the_root_to_exit_2(tmp_path, monkeypatch, capsys):
    from cli.errors import EXIT_BAD_INPUT, run_with_error_mapping

    seq = write_sequence(tmp_path / "room", trajectory(2))
    (seq / "camera.json").unlink()
    monkeypatch.setattr("sys.argv", ["vtdslam", "run", str(seq), "--camera", '{"fx": 5, "fy": 500, "cx": 320, '
                                     '"cy": 240}', "--out", str(tmp_path / "o")])
    assert run_with_error_mapping(app) == EXIT_BAD_INPUT
    assert "fx must be within" in capsys.readouterr().err


def test_a_run_that_tracked_nothing_exits_2_saying_why(tmp_path, monkeypatch, capsys):
    import cv2
    import numpy as np

    from cli.errors import EXIT_BAD_INPUT, run_with_error_mapping

    seq = write_sequence(tmp_path / "room", trajectory(3))
    for depth in (seq / "depth").iterdir():
        cv2.imwrite(str(depth), np.zeros((480, 640), np.uint16))
    monkeypatch.setattr("sys.argv", ["vtdslam", "run", str(seq), "--out", str(tmp_path / "o"), "--preset",
                                     "orb-only", "--quiet"])
    assert run_with_error_mapping(app) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "no frame was tracked: 3 frames" in err and "valid depth" in err
    assert not (tmp_path / "o" / "trajectory.txt").exists()
