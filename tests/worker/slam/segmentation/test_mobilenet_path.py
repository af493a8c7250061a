"""The MobileNetV2 path of the pyramid: the teacher's weights imported exactly, levels that start as the pretrained
CNN, configs, checkpoints and a training run that starts from the teacher's weights."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from tests.worker.slam.segmentation.test_msnet_model import TINY
from tests.worker.slam.segmentation.test_training import _tiny_yolo
from worker.slam.errors import ConfigError
from worker.slam.segmentation.msnet import MsnetConfig, build_msnet
from worker.slam.segmentation.msnet.checkpoint import load_model, save_model
from worker.slam.segmentation.msnet.mobilenet import STAGE_CHANNELS, pretrained_state_dict, stages
from worker.slam.segmentation.train.config import presets
from worker.slam.segmentation.train.trainer import load_pretrained_cnn, param_groups, train

TINY_MNV2 = replace(TINY, cnn="mobilenetv2")
TEACHER = "models/deeplabv3_257_mv_gpu.tflite"


def _teacher(shared: Path) -> Path:
    pytest.importorskip("ai_edge_litert")
    path = shared / TEACHER
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    return path


def _kernel(tensors: dict, name: str) -> torch.Tensor:
    return torch.from_numpy(tensors[name]).permute(0, 3, 1, 2).contiguous()


def _deeplab_head(tensors: dict, feat: torch.Tensor) -> torch.Tensor:
    """The teacher's head (image pooling + 1x1 ASPP branch, projection, logits), written out for this test only."""
    def conv(x: torch.Tensor, name: str, bias: str = "Conv2D_bias") -> torch.Tensor:
        return F.conv2d(x, _kernel(tensors, f"{name}/weights"), torch.from_numpy(tensors[f"{name}/{bias}"].copy()))

    pool = F.relu(conv(feat.mean((2, 3), keepdim=True), "image_pooling")).expand(-1, -1, *feat.shape[-2:])
    y = F.relu(conv(torch.cat([pool, F.relu(conv(feat, "aspp0"))], 1), "concat_projection"))
    return conv(y, "logits/semantic")


def test_imported_mobilenet_reproduces_the_teacher(shared: Path) -> None:
    """The MobileNetV2 built at the teacher's output stride 8 with the imported weights, plus the teacher's head,
    gives the teacher's logits on a real photo: the layout, the weight transposes and the dilations are right."""
    from worker.slam.io.images import read_rgb
    from worker.slam.segmentation.tflite_teacher import TfliteSegmenter, read_constants

    path = _teacher(shared)
    tensors = read_constants(path)
    cnn = stages(output_stride=8)
    cnn.load_state_dict(pretrained_state_dict(tensors))
    teacher = TfliteSegmenter(path)
    x = teacher._input(read_rgb(shared / "data" / "ccp_persons" / "images" / "0005.jpg"))
    teacher.interpreter.set_tensor(teacher._in_index, x)
    teacher.interpreter.invoke()
    want = teacher.interpreter.get_tensor(teacher._out_index)[0]
    with torch.no_grad():
        feat = torch.from_numpy(x).permute(0, 3, 1, 2)
        for stage in cnn:
            feat = stage(feat)
        logits = F.interpolate(_deeplab_head(tensors, feat), size=want.shape[:2], mode="bilinear",
                               align_corners=True)[0].permute(1, 2, 0).numpy()
    assert feat.shape == (1, STAGE_CHANNELS[-1], 33, 33)
    assert np.abs(logits - want).max() < 1e-3 * np.abs(want).max()
    assert (logits.argmax(-1) == want.argmax(-1)).mean() > 0.999


def test_levels_start_as_the_pretrained_cnn() -> None:
    """At initialisation the PEncoder branches add nothing to the CNN chain (their return projection starts at
    zero), so the pretrained stages see exactly the inputs they were trained on."""
    torch.manual_seed(0)
    model = build_msnet(TINY_MNV2).eval()
    x = torch.rand(1, 3, *TINY.input_size) * 2 - 1
    with torch.no_grad():
        chain = model.backbone.stem(x)
        for level in model.backbone.levels:
            chain, feat = level(chain)
        plain = x
        for stage in model.backbone.cnn_stages():
            plain = stage(plain)
    assert torch.equal(chain, plain) and feat.shape[1] == TINY.widths[-1]


def test_forward_gradients_and_checkpoint_round_trip(tmp_path: Path) -> None:
    torch.manual_seed(0)
    model = build_msnet(TINY_MNV2).train()
    out = model(torch.rand(2, 3, *TINY.input_size))
    assert out.logits.shape == (2, 3, *TINY.input_size)
    F.cross_entropy(out.logits, torch.randint(0, 3, (2, *TINY.input_size))).backward()
    # The return projections' convs get a gradient only once their zero-started BatchNorm scale moves.
    missing = [n for n, p in model.named_parameters()
               if (p.grad is None or not torch.any(p.grad != 0)) and ".back.0." not in n]
    assert not missing, missing
    save_model(tmp_path / "m.pt", model.eval())
    loaded, _ = load_model(tmp_path / "m.pt")
    x = torch.rand(1, 3, *TINY.input_size)
    with torch.no_grad():
        assert loaded.cfg.cnn == "mobilenetv2" and torch.equal(loaded(x).logits, model(x).logits)


def test_config_rejects_unknown_paths_and_level_counts() -> None:
    with pytest.raises(ConfigError):
        MsnetConfig(cnn="resnet")
    with pytest.raises(ConfigError):
        MsnetConfig(cnn="mobilenetv2", widths=(64, 96), depths=(1, 1), patch_sizes=(1, 1))
    assert MsnetConfig.from_dict(TINY_MNV2.to_dict()) == TINY_MNV2
    assert MsnetConfig.from_dict({k: v for k, v in TINY.to_dict().items() if k != "cnn"}).cnn == "plain"


def test_pretrained_init_needs_the_mobilenet_path(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="mobilenetv2"):
        load_pretrained_cnn(build_msnet(TINY), tmp_path / "none.tflite")


def test_training_starts_from_the_teachers_weights(shared: Path, tmp_path: Path) -> None:
    """A one-epoch run with `init_pretrained`: the pretrained layers train at their own rate, and the first
    stage's stem conv still carries the teacher's kernel to within that small rate's steps."""
    from worker.slam.segmentation.tflite_teacher import read_constants

    path = _teacher(shared)
    _tiny_yolo(tmp_path / "data")
    cfg = replace(presets()["smoke"], model=TINY_MNV2, yolo_dirs=(str(tmp_path / "data"),), backgrounds=(),
                  out_dir=str(tmp_path / "run"), holdout_every=3, threads=1, init_pretrained=str(path),
                  pretrained_lr_scale=0.1, ema_decay=0.0)
    groups = param_groups(build_msnet(TINY_MNV2), cfg)
    assert [g["lr_scale"] for g in groups] == [0.1, 1.0]
    assert sum(p.numel() for p in groups[0]["params"]) == sum(
        p.numel() for p in stages().parameters())
    model, _ = load_model(train(cfg, progress=False))
    start = _kernel(read_constants(path), "MobilenetV2/Conv/weights")
    got = next(model.backbone.stem.parameters())  # the stem conv's kernel
    assert torch.allclose(got, start, atol=0.05 * float(start.abs().max())) and not torch.equal(got, start)
