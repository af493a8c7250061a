"""`vtdslam synth`, `augment` and `demo` from the command line; the demo must work without ../shared."""
from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from cli.main import app
from tests.worker.slam.test_augment import make_coco
from worker.slam.errors import ConfigError
from worker.slam.io.sequence import Sequence
from worker.slam.truth import load_truth


def test_synth_command(tmp_path):
    out = tmp_path / "seq"
    res = CliRunner().invoke(app, ["synth", str(out), "--frames", "4", "--people", "1", "--trajectory", "circle",
                                   "--seed", "1"])
    assert res.exit_code == 0, res.output
    assert "wrote 4 frames" in res.output and len(Sequence(out)) == 4 and len(load_truth(out)) == 4


def test_synth_rejects_unknown_trajectory(tmp_path):
    res = CliRunner().invoke(app, ["synth", str(tmp_path / "x"), "--trajectory", "zigzag"])
    assert res.exit_code != 0 and isinstance(res.exception, ConfigError)


def test_demo_without_shared_data(tmp_path):
    empty = tmp_path / "no_shared"
    empty.mkdir()
    env = {"VTD_SHARED_DIR": str(empty), "VTD_DATA_DIR": str(tmp_path / "data")}
    runner = CliRunner()
    res = runner.invoke(app, ["demo", "--frames", "6"], env=env)
    assert res.exit_code == 0, res.output
    demo = tmp_path / "data" / "demo"
    truth = load_truth(demo)
    assert truth is not None and len(truth) == 6 and len(Sequence(demo)) == 6
    meta = json.loads((demo / "truth" / "truth.json").read_text())
    assert meta["generator"]["source"] == "walk"  # the built-in path: no real trajectory needed
    again = runner.invoke(app, ["demo", "--frames", "6", "--preset", "orb-only"], env=env)
    assert again.exit_code == 0 and "already" in again.output
    # both runs registered the sequence in place and queued a job for the service's worker
    from storage.db import make_engine, make_session_factory
    from storage.repositories import jobs
    from storage.settings import get_settings

    engine = make_engine(get_settings(data_dir=tmp_path / "data"))
    with make_session_factory(engine)() as session:
        queued = jobs.list_jobs(session)
    engine.dispose()
    assert sorted(j.preset for j in queued) == ["full", "orb-only"]
    assert all(j.status.value == "queued" for j in queued)


def test_augment_command(tmp_path):
    src = tmp_path / "static"
    assert CliRunner().invoke(app, ["synth", str(src), "--frames", "12", "--people", "0",
                                    "--trajectory", "circle"]).exit_code == 0
    coco = make_coco(tmp_path / "coco", np.random.default_rng(0))
    out = tmp_path / "aug"
    res = CliRunner().invoke(app, ["augment", str(src), "--people-from", str(coco), str(out), "--frames", "12",
                                   "--people", "1"])
    assert res.exit_code == 0, res.output
    assert "people cover" in res.output and len(load_truth(out)) == 12
