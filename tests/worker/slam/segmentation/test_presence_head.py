"""The class-presence head (issue 57): an absent class is suppressed everywhere, the presence loss sees which
classes an image holds, and the ablation switches build networks without the part they name."""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest
import torch

from worker.slam.segmentation.classes import VOC_CLASSES
from worker.slam.segmentation.msnet import MsnetConfig, build_msnet
from worker.slam.segmentation.msnet.heads import presence_logits
from worker.slam.segmentation.msnet.model import MsnetOutput
from worker.slam.segmentation.train.losses import msnet_loss, presence_targets

TINY = MsnetConfig(input_size=(64, 96), stem_channels=8, widths=(16, 16, 24), depths=(1, 1, 1), heads=2,
                   embed_dim=16, filters_per_class=4, decoder_layers=1, classes=VOC_CLASSES,
                   dynamic_classes=("person", "car"), class_head="presence")


def test_absent_class_is_suppressed_and_background_is_not() -> None:
    torch.manual_seed(0)
    pixel, embed = torch.randn(1, 8, 4, 5), torch.randn(1, 3, 8)
    present = presence_logits(pixel, torch.tensor([[0.0, 8.0, 8.0]]), embed)
    absent = presence_logits(pixel, torch.tensor([[-8.0, -8.0, 8.0]]), embed)
    assert torch.allclose(present[:, 0], absent[:, 0])  # the background is never gated
    assert (absent[:, 1] < present[:, 1] - 7.9).all()  # class 1 lowered by ~8 everywhere
    assert torch.allclose(present[:, 2], absent[:, 2])


def test_presence_targets_from_hard_labels_and_teacher() -> None:
    hard = torch.zeros(2, 20, 20, dtype=torch.long)
    hard[0, :5, :5] = 3  # 25 of 400 pixels: present
    hard[1, 0, 0] = 4  # 1 pixel of 400 (0.25 %): present at the 0.2 % floor
    hard[1, 1:, :] = 255  # ignored pixels count for nothing
    soft = torch.zeros(2, 6, 20, 20)
    soft[:, 0] = 1.0
    soft[0, 5, 10:, 10:], soft[0, 0, 10:, 10:] = 1.0, 0.0  # the teacher sees class 5 in image 0
    t = presence_targets(hard, soft, torch.ones(2, 20, 20), 6)
    assert t[0].tolist() == [1, 0, 0, 1, 0, 1]
    assert t[1].tolist() == [1, 0, 0, 0, 1, 0]


def test_presence_loss_trains_the_class_head() -> None:
    torch.manual_seed(0)
    model = build_msnet(TINY).train()
    out = model(torch.rand(2, 3, *TINY.input_size))
    assert isinstance(out, MsnetOutput) and out.class_logits.shape == (2, len(VOC_CLASSES))
    hard = torch.zeros(2, *TINY.input_size, dtype=torch.long)
    hard[0, 10:30, 10:30] = VOC_CLASSES.index("person")
    soft = torch.nn.functional.one_hot(hard, len(VOC_CLASSES)).permute(0, 3, 1, 2).float()
    loss, parts = msnet_loss(out, hard, soft, torch.ones(2, *TINY.input_size), torch.ones(len(VOC_CLASSES)),
                             1.0, 0.5)
    loss.backward()
    assert parts["query"] > 0
    head = model.enhancement.decoder.class_head
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in head.parameters())


@pytest.mark.parametrize("switch", ["pencoders", "enhancement_filters", "guidance_attention", "decoder"])
def test_ablations_drop_their_part(switch: str) -> None:
    flags: dict[str, Any] = {switch: False}
    full, ablated = build_msnet(TINY), build_msnet(replace(TINY, **flags))
    gone = {k.rsplit(".", 1)[0] for k in full.state_dict()} - {k.rsplit(".", 1)[0] for k in ablated.state_dict()}
    assert gone, f"{switch}=False removed no weights"
    with torch.no_grad():
        out = ablated.eval()(torch.rand(1, 3, *TINY.input_size))
    assert out.logits.shape == (1, len(VOC_CLASSES), *TINY.input_size)
    if switch == "decoder":  # no decoder: the class scores cannot depend on the image
        with torch.no_grad():
            other = ablated(torch.rand(1, 3, *TINY.input_size))
        assert torch.allclose(out.class_logits, other.class_logits)


def test_default_config_is_the_identity_head() -> None:
    """Checkpoints saved before the presence head have no class_head key: they keep the identity head."""
    data = MsnetConfig().to_dict()
    del data["class_head"]
    assert MsnetConfig.from_dict(data).class_head == "identity"
