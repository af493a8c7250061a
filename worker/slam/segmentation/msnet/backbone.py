"""Residual dual-pyramid backbone: C_i -> P_i (downsampled) -> PEncoder -> concat with P_i -> fused C_{i+1}."""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from worker.slam.segmentation.msnet.blocks import conv_bn_act, resize_pos_embed
from worker.slam.segmentation.msnet.config import MsnetConfig


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
        self.encoder = PEncoder(c_out, depth, patch, cfg.heads, cfg.mlp_ratio, cfg.dropout, grid)
        self.fuse = conv_bn_act(2 * c_out, c_out, 1)

    def forward(self, c: torch.Tensor) -> torch.Tensor:
        p = self.down(c)
        return p + self.fuse(torch.cat([self.encoder(p), p], dim=1))


class DualPyramidBackbone(nn.Module):
    """Image (B, 3, H, W) -> C1 (B, stem, H/4, W/4) and C5 (B, embed_dim, H/8, W/8)."""

    def __init__(self, cfg: MsnetConfig) -> None:
        super().__init__()
        h, w = cfg.input_size
        half = max(cfg.stem_channels // 2, 8)
        self.stem = nn.Sequential(conv_bn_act(3, half, 3, 2), conv_bn_act(half, cfg.stem_channels, 3, 2))
        levels, c_in = [], cfg.stem_channels
        for i, (c_out, depth, patch) in enumerate(zip(cfg.widths, cfg.depths, cfg.patch_sizes)):
            stride = 2 ** (i + 3)
            levels.append(PyramidLevel(c_in, c_out, depth, patch, cfg, (h // stride, w // stride)))
            c_in = c_out
        self.levels = nn.ModuleList(levels)
        # C5 = all levels projected to a common width at stride 8 and fused.
        self.lateral = nn.ModuleList(nn.Conv2d(c, cfg.embed_dim, 1) for c in cfg.widths)
        self.fuse = conv_bn_act(cfg.embed_dim * len(cfg.widths), cfg.embed_dim, 1)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        c1 = self.stem(x)
        feats, c = [], c1
        for level in self.levels:
            c = level(c)
            feats.append(c)
        size = feats[0].shape[-2:]
        lat = [F.interpolate(conv(f), size=size, mode="bilinear", align_corners=False) if i else conv(f)
               for i, (conv, f) in enumerate(zip(self.lateral, feats))]
        return c1, self.fuse(torch.cat(lat, dim=1))
