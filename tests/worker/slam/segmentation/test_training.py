"""Training: the loss falls on a tiny synthetic batch; the loop runs, logs, checkpoints and resumes; configs."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from tests.worker.slam.segmentation.test_msnet_model import TINY
from worker.slam.errors import ConfigError
from worker.slam.segmentation.msnet import build_msnet
from worker.slam.segmentation.msnet.checkpoint import export_model, load_model
from worker.slam.segmentation.train.config import load_train_config, presets
from worker.slam.segmentation.train.losses import msnet_loss
from worker.slam.segmentation.train.trainer import train


def test_training_steps_reduce_loss() -> None:
    torch.manual_seed(0)
    model = build_msnet(TINY).train()
    x = torch.rand(2, 3, *TINY.input_size)
    hard = torch.zeros(2, *TINY.input_size, dtype=torch.long)
    hard[:, 16:48, 20:50] = 1  # a "person" box
    x[:, 0, 16:48, 20:50] += 0.5
    soft = torch.nn.functional.one_hot(hard, 3).permute(0, 3, 1, 2).float()
    kd = torch.ones(2, *TINY.input_size)
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3)
    losses = []
    for _ in range(12):
        loss, parts = msnet_loss(model(x), hard, soft, kd, torch.ones(3), 1.0, 0.1)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(parts["loss"])
    assert np.isfinite(losses).all()
    assert losses[-1] < 0.7 * losses[0], losses


def _tiny_yolo(root: Path) -> None:
    rng = np.random.default_rng(0)
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    for i in range(6):
        img = rng.integers(0, 255, (60, 80, 3), dtype=np.uint8)
        cv2.imwrite(str(root / "images" / f"{i}.png"), img)
        (root / "labels" / f"{i}.txt").write_text("0 0.2 0.2 0.6 0.2 0.6 0.9 0.2 0.9\n")


def test_train_loop_logs_checkpoints_and_resumes(tmp_path: Path) -> None:
    _tiny_yolo(tmp_path / "data")
    cfg = replace(presets()["smoke"], model=TINY, yolo_dirs=(str(tmp_path / "data"),), backgrounds=(),
                  out_dir=str(tmp_path / "run"), holdout_every=3, threads=1)
    weights = train(cfg, progress=False)
    model, meta = load_model(weights)
    assert model.cfg == TINY and meta["epoch"] == 1
    train(replace(cfg, epochs=2), resume=True, progress=False)
    lines = [json.loads(x) for x in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in lines] == [1, 2]
    assert {"loss", "ce", "kd", "val_miou", "val_iou", "elapsed_s"} <= set(lines[0])


def test_train_config_presets_and_files(tmp_path: Path) -> None:
    paper = load_train_config("paper")
    assert (paper.lr, paper.epochs, paper.batch_size, paper.model.dropout) == (1e-3, 64, 4, 0.56)
    f = tmp_path / "c.json"
    f.write_text(json.dumps({"preset": "smoke", "epochs": 3, "model": {"embed_dim": 32}}))
    cfg = load_train_config(str(f), lr=0.5)
    assert (cfg.epochs, cfg.model.embed_dim, cfg.lr, cfg.teacher) == (3, 32, 0.5, None)
    f.write_text(json.dumps({"nope": 1}))
    with pytest.raises(ConfigError):
        load_train_config(str(f))
    with pytest.raises(ConfigError):
        load_train_config("no-such-preset")


def test_fine_tuning_starts_from_the_given_weights(tmp_path: Path) -> None:
    _tiny_yolo(tmp_path / "data")
    base = replace(presets()["smoke"], model=TINY, yolo_dirs=(str(tmp_path / "data"),), backgrounds=(),
                   holdout_every=3, threads=1)
    first = train(replace(base, out_dir=str(tmp_path / "a")), progress=False)
    # lr 0 freezes the weights: what comes out is what went in (fine-tuned) or a new random draw (not)
    tuned = train(replace(base, out_dir=str(tmp_path / "b"), init_weights=str(first), lr=0.0, seed=5),
                  progress=False)
    fresh = train(replace(base, out_dir=str(tmp_path / "c"), lr=0.0, seed=5), progress=False)
    start = dict(load_model(first)[0].named_parameters())
    assert all(torch.equal(p, start[k]) for k, p in load_model(tuned)[0].named_parameters())
    assert not all(torch.equal(p, start[k]) for k, p in load_model(fresh)[0].named_parameters())
    with pytest.raises(ConfigError, match="architecture"):
        train(replace(base, out_dir=str(tmp_path / "d"), init_weights=str(first), model=replace(TINY, embed_dim=32)),
              progress=False)
    # An exported checkpoint that narrows the dynamic classes (`export-msnet --dynamic-classes`) still starts one.
    exported = tmp_path / "exported.pt"
    export_model(first, exported, dynamic_classes=("person",))
    train(replace(base, out_dir=str(tmp_path / "e"), init_weights=str(exported), lr=0.0), progress=False)


@pytest.mark.parametrize("preset", ["cpu-tum-ft", "cpu-real-tum-ft", "cpu-real-mnv2-neg"])
def test_cli_rejects_fine_tuning_without_weights(tmp_path: Path, capsys, monkeypatch, preset: str) -> None:
    from cli.errors import run_with_error_mapping
    from cli.main import app

    monkeypatch.setattr("sys.argv", ["vtdslam", "train-msnet", "--config", preset, "--out", str(tmp_path)])
    assert run_with_error_mapping(app) == 2
    assert "--init" in capsys.readouterr().err and not any(tmp_path.iterdir())
