"""`vtdslam augment --movers ... --static N` from the command line."""
from __future__ import annotations

import numpy as np
from typer.testing import CliRunner

from cli.main import app
from tests.worker.slam.test_augment import make_coco
from worker.slam.errors import ConfigError
from worker.slam.truth import load_truth


def _static_source(tmp_path):
    src = tmp_path / "static"
    res = CliRunner().invoke(app, ["synth", str(src), "--frames", "10", "--people", "0", "--trajectory", "circle"])
    assert res.exit_code == 0, res.output
    return src


def test_augment_with_movers_and_static_instances(tmp_path):
    src, coco, out = _static_source(tmp_path), make_coco(tmp_path / "coco", np.random.default_rng(0)), tmp_path / "aug"
    res = CliRunner().invoke(app, ["augment", str(src), "--people-from", str(coco), str(out), "--frames", "10",
                                   "--people", "1", "--movers", "chair", "--static", "1", "--static-classes", "object"])
    assert res.exit_code == 0, res.output
    assert "movers cover" in res.output
    gen = load_truth(out).layout.generator
    assert gen["movers"] == ["chair"] and [s["class"] for s in gen["static"]] == ["chair"]
    assert len(list((out / "truth/classes").glob("*.png"))) == len(list((out / "truth/static").glob("*.png"))) == 10


def test_augment_rejects_an_unknown_mover(tmp_path):
    src, coco = _static_source(tmp_path), make_coco(tmp_path / "coco", np.random.default_rng(0))
    res = CliRunner().invoke(app, ["augment", str(src), "--people-from", str(coco), str(tmp_path / "aug"),
                                   "--movers", "dragon"])
    assert res.exit_code != 0 and isinstance(res.exception, ConfigError) and "dragon" in str(res.exception)
    assert not (tmp_path / "aug").exists()  # nothing half-written
