"""Residual dual-pyramid backbone: C_i -> P_i (downsampled) -> PEncoder -> concat with P_i -> fused C_{i+1}.

The downsampling path is a conv per level (`cnn` "plain") or the stages of a MobileNetV2 (`cnn` "mobilenetv2"),
which training can start from pretrained weights (`load_pretrained_cnn`)."""
from __future__ import annotations

from typing import cast

import torch
import torch.nn.functional as F
from torch import nn

from worker.slam.segmentation.msnet.blocks import conv_bn_act, resize_pos_embed
from worker.slam.segmentation.msnet.config import MsnetConfig
from worker.slam.segmentation.msnet.mobilenet import STAGE_CHANNELS, stages


class PEncoder(nn.Module):
    """Patch embedding + position embedding + Transformer encoder (MHSA, dropout, MLP, LayerNorm) on a map."""

    def __init__(self, dim: int, depth: int, patch: int, heads: int, mlp_ratio: float, dropout: float,
                 grid: tuple[int, int]) -> None:
        super().__init__()
        self.patch = patch
        self.embed = nn.Conv2d(dim, dim, patch, patch)
        self.pos = nn.Parameter(torch.zeros(1, dim, grid[0] // patch, grid[1] // patch))
        nn.init.trunc_normal_(self.pos, std=0.02)
        layer = nn.TransformerEncoderLayer(dim, heads, int(dim * mlp_ratio), dropout, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, depth, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x (B, C, H, W) -> encoded (B, C, H, W); tokens are patches of `patch` x `patch` pixels."""
        b, c, h, w = x.shape
        t = self.embed(x)
        gh, gw = t.shape[-2:]
        t = t + resize_pos_embed(self.pos, (gh, gw))
        t = self.norm(self.encoder(t.flatten(2).transpose(1, 2)))
        t = t.transpose(1, 2).reshape(b, c, gh, gw)
        if self.patch > 1:
            t = F.interpolate(t, size=(h, w), mode="bilinear", align_corners=False)
        return t


class PyramidLevel(nn.Module):
    """One level: P = down(C); C_next = P + fuse([PEncoder(P), P]) (the residual keeps the CNN path trainable)."""

    def __init__(self, c_in: int, c_out: int, depth: int, patch: int, cfg: MsnetConfig,
                 grid: tuple[int, int]) -> None:
        super().__init__()
        self.down = conv_bn_act(c_in, c_out, 3, 2)
        self.encoder = PEncoder(c_out, depth, patch, cfg.heads, cfg.mlp_ratio, cfg.dropout, grid) \
            if cfg.pencoders else None
        self.fuse = conv_bn_act(2 * c_out, c_out, 1) if cfg.pencoders else None

    def forward(self, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """-> (C_next for the next level, the level's feature for C5): the same map here."""
        p = self.down(c)
        if self.encoder is not None and self.fuse is not None:
            p = p + self.fuse(torch.cat([self.encoder(p), p], dim=1))
        return p, p


class StageLevel(nn.Module):
    """A level over a pretrained CNN stage: P = stage(C) keeps the stage's channels; the PEncoder works at `width`
    on a projection Q of P, and Q + fuse([PEncoder(Q), Q]) returns into P through a projection whose BatchNorm
    starts at zero, so training begins with the pretrained CNN path unchanged. The last level has no next stage,
    hence no return projection (`returns` False)."""

    def __init__(self, stage: nn.Module, c_stage: int, width: int, depth: int, patch: int, cfg: MsnetConfig,
                 grid: tuple[int, int], returns: bool = True) -> None:
        super().__init__()
        self.stage = stage
        self.project = conv_bn_act(c_stage, width, 1)
        # Without PEncoders (an ablation) the level is the stage and its projection for C5.
        self.encoder = PEncoder(width, depth, patch, cfg.heads, cfg.mlp_ratio, cfg.dropout, grid) \
            if cfg.pencoders else None
        self.fuse = conv_bn_act(2 * width, width, 1) if cfg.pencoders else None
        scale = nn.BatchNorm2d(c_stage)
        nn.init.zeros_(scale.weight)
        self.back = nn.Sequential(nn.Conv2d(width, c_stage, 1, bias=False), scale) \
            if returns and cfg.pencoders else None

    def forward(self, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """-> (C_next (stage channels) for the next stage, Q (width channels) for C5)."""
        p = self.stage(c)
        q = self.project(p)
        if self.encoder is None or self.fuse is None:
            return p, q
        q = q + self.fuse(torch.cat([self.encoder(q), q], dim=1))
        return (p + self.back(q) if self.back is not None else p), q


class DualPyramidBackbone(nn.Module):
    """Image (B, 3, H, W) -> C1 (B, stem, H/4, W/4) and C5 (B, embed_dim, H/8, W/8)."""

    def __init__(self, cfg: MsnetConfig) -> None:
        super().__init__()
        h, w = cfg.input_size
        grids = [(h // 2 ** (i + 3), w // 2 ** (i + 3)) for i in range(len(cfg.widths))]
        levels: list[nn.Module] = []
        if cfg.cnn == "mobilenetv2":
            cnn = stages()
            # The chain runs on the stage's own 12 channels; C1 for the guidance is their projection.
            self.stem = cnn[0]
            self.skip: nn.Module = conv_bn_act(STAGE_CHANNELS[0], cfg.stem_channels, 1)
            for i, (width, depth, patch) in enumerate(zip(cfg.widths, cfg.depths, cfg.patch_sizes)):
                levels.append(StageLevel(cnn[i + 1], STAGE_CHANNELS[i + 1], width, depth, patch, cfg, grids[i],
                                         returns=i + 1 < len(cfg.widths)))
        else:
            half = max(cfg.stem_channels // 2, 8)
            self.stem = nn.Sequential(conv_bn_act(3, half, 3, 2), conv_bn_act(half, cfg.stem_channels, 3, 2))
            self.skip = nn.Identity()
            c_in = cfg.stem_channels
            for i, (c_out, depth, patch) in enumerate(zip(cfg.widths, cfg.depths, cfg.patch_sizes)):
                levels.append(PyramidLevel(c_in, c_out, depth, patch, cfg, grids[i]))
                c_in = c_out
        self.levels = nn.ModuleList(levels)
        # C5 = all levels projected to a common width at stride 8 and fused.
        self.lateral = nn.ModuleList(nn.Conv2d(c, cfg.embed_dim, 1) for c in cfg.widths)
        self.fuse = conv_bn_act(cfg.embed_dim * len(cfg.widths), cfg.embed_dim, 1)

    def cnn_stages(self) -> nn.ModuleList:
        """The MobileNetV2 stages in `mobilenet.stages()` order (for `load_pretrained_cnn`)."""
        return nn.ModuleList([self.stem, *(cast(StageLevel, level).stage for level in self.levels)])

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        c = self.stem(x)
        c1 = self.skip(c)
        feats = []
        for level in self.levels:
            c, feat = level(c)
            feats.append(feat)
        size = feats[0].shape[-2:]
        lat = [F.interpolate(conv(f), size=size, mode="bilinear", align_corners=False) if i else conv(f)
               for i, (conv, f) in enumerate(zip(self.lateral, feats))]
        return c1, self.fuse(torch.cat(lat, dim=1))
