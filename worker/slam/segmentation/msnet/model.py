"""MSNET: backbone -> multiclass feature enhancement -> multiclass feature guidance -> class x mask head."""
from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from worker.slam.segmentation.msnet.backbone import DualPyramidBackbone
from worker.slam.segmentation.msnet.config import MsnetConfig
from worker.slam.segmentation.msnet.enhancement import FeatureEnhancement
from worker.slam.segmentation.msnet.guidance import FeatureGuidance
from worker.slam.segmentation.msnet.heads import ClassMaskHead


class MsnetFeatures(NamedTuple):
    pixel: torch.Tensor  # (B, D, H/4, W/4) pixel embedding
    class_logits: torch.Tensor  # (B, M, M) query q's logits over the M classes, or (B, M) presence logits
    mask_embed: torch.Tensor  # (B, M, D)


class MsnetOutput(NamedTuple):
    logits: torch.Tensor  # (B, M, H, W) per-class logits at the input size
    class_logits: torch.Tensor  # "identity": (B, M, M), query q trained to predict class q; "presence": (B, M)


class MSNet(nn.Module):
    """Input: normalised RGB (B, 3, H, W), H and W multiples of 32. Output: `MsnetOutput`."""

    mean: torch.Tensor  # (1, 3, 1, 1) buffers, registered in __init__
    std: torch.Tensor

    def __init__(self, cfg: MsnetConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.backbone = DualPyramidBackbone(cfg)
        self.enhancement = FeatureEnhancement(cfg)
        self.guidance = FeatureGuidance(cfg.embed_dim, cfg.stem_channels, cfg.refine_rank, cfg.guidance_attention)
        self.head = ClassMaskHead(cfg.class_head)
        # Inputs are uint8-derived RGB in [0, 1]: ImageNet statistics, or [-1, 1] as the MobileNetV2 was trained.
        mean, std = ([0.5] * 3, [0.5] * 3) if cfg.cnn == "mobilenetv2" else ([0.485, 0.456, 0.406],
                                                                             [0.229, 0.224, 0.225])
        self.register_buffer("mean", torch.tensor(mean).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(std).view(1, 3, 1, 1), persistent=False)

    def forward_features(self, x: torch.Tensor) -> MsnetFeatures:
        """x (B, 3, H, W) RGB in [0, 1]."""
        c1, c5 = self.backbone((x - self.mean) / self.std)
        enhanced, class_logits, mask_embed = self.enhancement(c5)
        return MsnetFeatures(self.guidance(enhanced, c1), class_logits, mask_embed)

    def forward_head(self, feats: MsnetFeatures, out_size: tuple[int, int]) -> MsnetOutput:
        logits = self.head(feats.pixel, feats.class_logits, feats.mask_embed, out_size)
        return MsnetOutput(logits, feats.class_logits)

    def forward_grid(self, x: torch.Tensor) -> torch.Tensor:
        """x (B, 3, H, W) -> logits (B, M, H/4, W/4) on the pixel embedding's grid, before the upsampling."""
        feats = self.forward_features(x)
        return self.head.grid(feats.pixel, feats.class_logits, feats.mask_embed)

    def forward(self, x: torch.Tensor) -> MsnetOutput:
        return self.forward_head(self.forward_features(x), (x.shape[-2], x.shape[-1]))


def build_msnet(cfg: MsnetConfig | None = None) -> MSNet:
    """Factory for a freshly initialised model (default: the shipped CPU size)."""
    return MSNet(cfg or MsnetConfig())
