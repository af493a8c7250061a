"""Forward tests of MSNET: shapes, finite outputs, and gradients reaching every parameter and module."""
from __future__ import annotations

import pytest
import torch

from tests.worker.slam.segmentation.helpers import randomise_batchnorm
from worker.slam.errors import ConfigError
from worker.slam.segmentation.msnet import MsnetConfig, build_msnet
from worker.slam.segmentation.msnet.blocks import fold_batchnorm

TINY = MsnetConfig(input_size=(64, 96), stem_channels=8, widths=(16, 16, 24), depths=(1, 1, 1), heads=2,
                   embed_dim=16, filters_per_class=4, decoder_layers=1)


@pytest.mark.parametrize("cfg", [TINY, MsnetConfig()], ids=["tiny", "default"])
def test_forward_shapes_and_finite(cfg: MsnetConfig) -> None:
    torch.manual_seed(0)
    model = build_msnet(cfg).eval()
    x = torch.rand(2, 3, *cfg.input_size)
    with torch.no_grad():
        out = model(x)
    assert out.logits.shape == (2, cfg.num_classes, *cfg.input_size)
    assert out.class_logits.shape == (2, cfg.num_classes, cfg.num_classes)
    assert torch.isfinite(out.logits).all() and torch.isfinite(out.class_logits).all()


def test_other_input_size_and_feature_split() -> None:
    """Position embeddings are resampled, so a different (multiple-of-32) size works; the head is separable."""
    model = build_msnet(TINY).eval()
    with torch.no_grad():
        feats = model.forward_features(torch.rand(1, 3, 96, 128))
        out = model.forward_head(feats, (96, 128))
    assert feats.pixel.shape == (1, TINY.embed_dim, 24, 32)
    assert out.logits.shape == (1, 3, 96, 128)


def test_gradients_reach_every_parameter() -> None:
    torch.manual_seed(0)
    model = build_msnet(TINY).train()
    out = model(torch.rand(2, 3, *TINY.input_size))
    target = torch.randint(0, 3, (2, *TINY.input_size))
    loss = torch.nn.functional.cross_entropy(out.logits, target) + out.class_logits.square().mean()
    loss.backward()
    missing = [n for n, p in model.named_parameters() if p.grad is None or not torch.any(p.grad != 0)]
    assert not missing, f"no gradient for {missing}"
    for name in ("backbone", "enhancement", "guidance"):
        assert any(p.grad is not None for p in getattr(model, name).parameters())


def test_config_validation() -> None:
    with pytest.raises(ConfigError):
        MsnetConfig(classes=("person", "background"))
    with pytest.raises(ConfigError):
        MsnetConfig(input_size=(100, 128))
    with pytest.raises(ConfigError):
        MsnetConfig(dynamic_classes=("car",))
    assert MsnetConfig.from_dict(MsnetConfig().to_dict()) == MsnetConfig()


def test_folded_batchnorm_gives_the_same_logits_and_leaves_the_model() -> None:
    """BN statistics away from their defaults, then folded: the same logits to float rounding, no BatchNorm2d
    left where a conv precedes it, and the original keeps its BN layers and its training mode."""
    torch.manual_seed(0)
    model = randomise_batchnorm(build_msnet(TINY))
    n_bn = sum(isinstance(m, torch.nn.BatchNorm2d) for m in model.modules())
    folded = fold_batchnorm(model)
    assert model.training and sum(isinstance(m, torch.nn.BatchNorm2d) for m in model.modules()) == n_bn > 0
    assert sum(isinstance(m, torch.nn.BatchNorm2d) for m in folded.modules()) == 0 and not folded.training
    x = torch.rand(1, 3, *TINY.input_size)
    model.eval()
    with torch.no_grad():
        want, got = model(x).logits, folded(x).logits
    assert torch.allclose(want, got, atol=1e-4) and not torch.equal(want, torch.zeros_like(want))
