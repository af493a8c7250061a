"""Multiclass feature enhancement: M per-class filters over C5, fused; a Transformer decoder with one query
per class; MLP heads giving per-query class logits (class head) and mask embeddings (mask head)."""
from __future__ import annotations

import torch
from torch import nn

from worker.slam.segmentation.msnet.blocks import Mlp, conv_bn_act, resize_pos_embed
from worker.slam.segmentation.msnet.config import MsnetConfig


class PerClassFilters(nn.Module):
    """M parallel 3x3 filter banks (one per class, as one grouped conv) fused back to C5's width, residually."""

    def __init__(self, dim: int, num_classes: int, per_class: int) -> None:
        super().__init__()
        self.split = nn.Conv2d(dim, num_classes * per_class, 1)
        # groups=num_classes keeps each class's filters looking only at its own slice.
        self.filters = nn.Sequential(
            nn.Conv2d(num_classes * per_class, num_classes * per_class, 3, padding=1, groups=num_classes,
                      bias=False),
            nn.BatchNorm2d(num_classes * per_class), nn.ReLU(inplace=True))
        self.fuse = conv_bn_act(num_classes * per_class, dim, 1)

    def forward(self, c5: torch.Tensor) -> torch.Tensor:
        return c5 + self.fuse(self.filters(self.split(c5)))


class ClassQueryDecoder(nn.Module):
    """Queries (B, M, D) attend to the enhanced map's tokens; returns class logits and mask embeddings."""

    def __init__(self, cfg: MsnetConfig) -> None:
        super().__init__()
        d, m = cfg.embed_dim, cfg.num_classes
        h, w = cfg.input_size
        self.queries = nn.Parameter(torch.randn(1, m, d) * 0.02)
        self.use_decoder = cfg.decoder
        if cfg.decoder:
            self.pos = nn.Parameter(torch.zeros(1, d, h // 8, w // 8))
            nn.init.trunc_normal_(self.pos, std=0.02)
            layer = nn.TransformerDecoderLayer(d, cfg.heads, int(d * cfg.mlp_ratio), cfg.dropout,
                                               activation="gelu", batch_first=True, norm_first=True)
            self.decoder = nn.TransformerDecoder(layer, cfg.decoder_layers, norm=nn.LayerNorm(d))
        self.presence = cfg.class_head == "presence"
        self.class_head = Mlp(d, d, 1 if self.presence else m, cfg.dropout)
        self.mask_head = Mlp(d, d, d, cfg.dropout)

    def forward(self, feat: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """feat (B, D, h, w) -> class logits ((B, M, M), or (B, M) presence logits) and mask embeddings (B, M, D)."""
        b = feat.shape[0]
        q = self.queries.expand(b, -1, -1)
        if self.use_decoder:
            memory = (feat + resize_pos_embed(self.pos, (feat.shape[-2], feat.shape[-1]))).flatten(2).transpose(1, 2)
            q = self.decoder(q, memory)
        logits = self.class_head(q)
        return (logits[..., 0] if self.presence else logits), self.mask_head(q)


class FeatureEnhancement(nn.Module):
    """C5 -> (enhanced C5, class logits (B, M, M), mask embeddings (B, M, D))."""

    def __init__(self, cfg: MsnetConfig) -> None:
        super().__init__()
        self.filters: nn.Module = PerClassFilters(cfg.embed_dim, cfg.num_classes, cfg.filters_per_class) \
            if cfg.enhancement_filters else nn.Identity()
        self.decoder = ClassQueryDecoder(cfg)

    def forward(self, c5: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        enhanced = self.filters(c5)
        class_logits, mask_embed = self.decoder(enhanced)
        return enhanced, class_logits, mask_embed
