"""The factorised refinement (`MsnetConfig.refine_rank`) and `vtdslam compress-msnet`: exact at full rank, an
approximation below it that distillation brings closer to the dense network, loadable and runnable like any
checkpoint."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from cli.main import app
from tests.worker.slam.segmentation.helpers import randomise_batchnorm, tiny_yolo_set
from tests.worker.slam.segmentation.test_msnet_model import TINY
from worker.slam.errors import ConfigError
from worker.slam.segmentation.msnet import MsnetConfig, build_msnet
from worker.slam.segmentation.msnet.blocks import fold_batchnorm
from worker.slam.segmentation.msnet.checkpoint import load_model, save_model
from worker.slam.segmentation.msnet.model import MSNet
from worker.slam.segmentation.train.compress import CompressConfig, distil_refine, factorise_refine


def _dense(seed: int = 0) -> MSNet:
    """TINY with BatchNorm statistics away from their defaults (so folding and copying them matter)."""
    torch.manual_seed(seed)
    model = build_msnet(TINY)
    randomise_batchnorm(model)
    return model.eval()


def _images(n: int, seed: int = 0) -> torch.Tensor:
    """(n, 3, H, W) smooth random images: blurred noise, so the network sees structure rather than pixel noise."""
    rng = np.random.default_rng(seed)
    h, w = TINY.input_size
    imgs = [cv2.GaussianBlur(rng.random((h, w, 3)).astype(np.float32), (0, 0), 3.0) for _ in range(n)]
    x = torch.from_numpy(np.stack(imgs)).permute(0, 3, 1, 2)
    return (x - x.amin()) / (x.amax() - x.amin())


def test_full_rank_is_the_dense_function_and_rank_one_is_not() -> None:
    dense = _dense()
    x = _images(2)
    with torch.no_grad():
        want = dense(x).logits
        full = factorise_refine(dense, 9)(x).logits
        low = factorise_refine(dense, 1)(x).logits
    assert torch.allclose(want, full, atol=1e-4)
    assert not torch.allclose(want, low, atol=1e-2)


def test_factorised_checkpoint_loads_folds_and_keeps_other_weights(tmp_path: Path) -> None:
    dense = _dense()
    student = factorise_refine(dense, 2)
    assert student.cfg.refine_rank == 2 and student.cfg == replace(dense.cfg, refine_rank=2)
    other = {k: v for k, v in dense.state_dict().items() if not k.startswith("guidance.refine.")}
    got = student.state_dict()
    assert all(torch.equal(v, got[k]) for k, v in other.items())
    save_model(tmp_path / "s.pt", student)
    loaded, _ = load_model(tmp_path / "s.pt")
    x = _images(1)
    with torch.no_grad():
        want = student(x).logits
        assert torch.equal(loaded(x).logits, want)
        assert torch.allclose(fold_batchnorm(loaded)(x).logits, want, atol=1e-4)  # the segmenter's BN folding
    with pytest.raises(ConfigError):
        factorise_refine(student, 1)


def test_refine_rank_config() -> None:
    assert MsnetConfig().refine_rank == 0
    legacy = {k: v for k, v in MsnetConfig().to_dict().items() if k != "refine_rank"}
    assert MsnetConfig.from_dict(legacy).refine_rank == 0  # checkpoints from before the option
    with pytest.raises(ConfigError):
        MsnetConfig(refine_rank=10)
    with pytest.raises(ConfigError):
        CompressConfig(rank=0)


def test_distillation_brings_the_student_closer_to_the_dense_network() -> None:
    dense = _dense()
    student = factorise_refine(dense, 1)
    before = [p.clone() for p in dense.parameters()]
    res = distil_refine(dense, student, _images(48), CompressConfig(rank=1, local_steps=80, steps=80, batch=8))
    assert res.kl < res.kl_svd and res.agreement >= res.agreement_svd
    assert all(torch.equal(a, b) for a, b in zip(before, dense.parameters()))  # the teacher is left alone
    assert not student.training


def test_compress_cli_writes_a_checkpoint_with_its_record(tmp_path: Path) -> None:
    root, bg = tiny_yolo_set(tmp_path, 6, "0 0.2 0.1 0.7 0.1 0.7 0.95 0.2 0.95\n")
    recipe = tmp_path / "recipe.json"
    recipe.write_text(json.dumps({"preset": "smoke", "yolo_dirs": [str(root)], "backgrounds": [str(bg / "*.jpg")],
                                  "background_stride": 1, "holdout_every": 0, "val_every": 3}))
    src, dest = tmp_path / "dense.pt", tmp_path / "out" / "small.pt"
    save_model(src, _dense(), {"epoch": 7})
    out = CliRunner().invoke(app, ["compress-msnet", str(src), str(dest), "--recipe", str(recipe), "--samples", "16",
                                   "--local-steps", "8", "--steps", "8", "--shared-dir", str(tmp_path)])
    assert out.exit_code == 0, out.output
    model, meta = load_model(dest)
    assert model.cfg.refine_rank == 1 and meta["epoch"] == 7 and meta["compressed_from"] == str(src)
    assert set(meta["compress"]["val_person_iou"]) == {"dense", "factorised"}
    bad = CliRunner().invoke(app, ["compress-msnet", str(dest), str(tmp_path / "x.pt"), "--recipe", str(recipe),
                                   "--shared-dir", str(tmp_path)])
    assert bad.exit_code == 2 and "already factorised" in bad.output and not (tmp_path / "x.pt").exists()
