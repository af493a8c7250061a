"""`vtdslam train-vocab` from the command line: a tiny tree from a few images; evaluation-only data refused."""
from __future__ import annotations

import cv2
from typer.testing import CliRunner

from cli.main import app
from tests.worker.slam.synthetic_room import pose, render
from worker.slam.features.vocabulary import Vocabulary


def test_train_vocab_command(tmp_path):
    imgs = tmp_path / "imgs"
    imgs.mkdir()
    for i, yaw in enumerate((0, 90, 180)):
        rgb, _ = render(pose([0.0, 0.0, 0.0], yaw))
        cv2.imwrite(str(imgs / f"{i}.jpg"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    out = tmp_path / "v.npz"
    res = CliRunner().invoke(app, ["train-vocab", "--out", str(out), "--images", str(imgs), "--k", "5",
                                   "--levels", "2", "--max-descriptors", "1000"])
    assert res.exit_code == 0, res.output
    assert "from 3 images" in res.output
    voc = Vocabulary.load(out)
    assert voc.k == 5 and voc.levels == 2 and 5 < voc.n_words <= 25


def test_train_vocab_refuses_evaluation_only_folders(tmp_path):
    bad = tmp_path / "davis_movers_dev"
    bad.mkdir()
    res = CliRunner().invoke(app, ["train-vocab", "--out", str(tmp_path / "v.npz"), "--images", str(bad)])
    assert res.exit_code == 2 and "evaluation-only" in res.output
