"""Multiclass feature guidance: channel and spatial attention (avg + max pooling, sigmoid), concatenated into a
dense global-semantic map, then upsampled with the stride-4 skip into the pixel embedding."""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from worker.slam.segmentation.msnet.blocks import conv_bn_act, separable_conv_bn_act


class ChannelAttention(nn.Module):
    """Per-channel gate from a shared MLP over the spatial average and maximum."""

    def __init__(self, dim: int, reduction: int = 4) -> None:
        super().__init__()
        hidden = max(dim // reduction, 4)
        self.mlp = nn.Sequential(nn.Conv2d(dim, hidden, 1), nn.ReLU(inplace=True), nn.Conv2d(hidden, dim, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        gate = self.mlp(x.mean((2, 3), keepdim=True)) + self.mlp(x.amax((2, 3), keepdim=True))
        return x * torch.sigmoid(gate)


class SpatialAttention(nn.Module):
    """Per-pixel gate from a 7x7 conv over the channel average and maximum."""

    def __init__(self, kernel: int = 7) -> None:
        super().__init__()
        self.conv = nn.Conv2d(2, 1, kernel, padding=kernel // 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        pooled = torch.cat([x.mean(1, keepdim=True), x.amax(1, keepdim=True)], dim=1)
        return x * torch.sigmoid(self.conv(pooled))


class FeatureGuidance(nn.Module):
    """(enhanced C5 (B, D, H/8, W/8), C1 (B, S, H/4, W/4)) -> pixel embedding (B, D, H/4, W/4).
    `refine_rank`: 0 = dense 3x3 refinement, r >= 1 = its rank-r separable stand-in (`MsnetConfig.refine_rank`).
    `attention` False (an ablation) passes the enhanced C5 to the upsampling without the two attentions."""

    def __init__(self, dim: int, skip_channels: int, refine_rank: int = 0, attention: bool = True) -> None:
        super().__init__()
        self.attention = attention
        if attention:
            self.channel = ChannelAttention(dim)
            self.spatial = SpatialAttention()
            self.merge = conv_bn_act(2 * dim, dim, 1)
        self.skip = conv_bn_act(skip_channels, dim, 1)
        self.refine = separable_conv_bn_act(dim, dim, refine_rank) if refine_rank else conv_bn_act(dim, dim, 3)
        self.embed = nn.Conv2d(dim, dim, 1)

    def forward(self, feat: torch.Tensor, c1: torch.Tensor) -> torch.Tensor:
        dense = self.merge(torch.cat([self.channel(feat), self.spatial(feat)], dim=1)) if self.attention else feat
        up = F.interpolate(dense, size=c1.shape[-2:], mode="bilinear", align_corners=False)
        return self.embed(self.refine(up + self.skip(c1)))
