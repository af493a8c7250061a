"""Segmentation head: the pixel embedding is multiplied by the mask head (one mask per query), the masks are
turned into class logits by the class head, then upsampled to the network's input size.

Two class heads (`MsnetConfig.class_head`): "identity" mixes the masks with each query's class distribution;
"presence" keeps query k's mask as class k's logits and adds log sigmoid(presence_k), so a class the decoder finds
absent from the image is suppressed everywhere (the background, index 0, is never gated)."""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def query_masks(pixel: torch.Tensor, mask_embed: torch.Tensor) -> torch.Tensor:
    """(pixel embedding (B, D, h, w), mask embeddings (B, Q, D)) -> mask logits (B, Q, h, w)."""
    # Scaled dot product keeps mask logits O(1) at init whatever the embedding width.
    return torch.einsum("bqd,bdhw->bqhw", mask_embed, pixel) / pixel.shape[1] ** 0.5


def grid_logits(pixel: torch.Tensor, class_probs: torch.Tensor, mask_embed: torch.Tensor) -> torch.Tensor:
    """The "identity" head: (pixel embedding (B, D, h, w), class distributions (B, Q, K), mask embeddings
    (B, Q, D)) -> logits (B, K, h, w) on the embedding's grid, before the upsampling."""
    # Linear in the masks, so the result is a logit map usable with cross-entropy directly.
    return torch.einsum("bqk,bqhw->bkhw", class_probs, query_masks(pixel, mask_embed))


def presence_logits(pixel: torch.Tensor, presence: torch.Tensor, mask_embed: torch.Tensor) -> torch.Tensor:
    """The "presence" head: (pixel embedding (B, D, h, w), presence logits (B, K), mask embeddings (B, K, D)) ->
    logits (B, K, h, w): class k's mask logits + log sigmoid(presence_k), the background's ungated."""
    gate = F.logsigmoid(presence)
    gate = torch.cat([torch.zeros_like(gate[:, :1]), gate[:, 1:]], dim=1)
    return query_masks(pixel, mask_embed) + gate[:, :, None, None]


class ClassMaskHead(nn.Module):
    """(pixel embedding (B, D, h, w), class logits ((B, Q, K) "identity" or (B, K) "presence"), mask embeddings
    (B, Q, D)) -> logits (B, K, H, W)."""

    def __init__(self, kind: str = "identity") -> None:
        super().__init__()
        self.kind = kind

    def grid(self, pixel: torch.Tensor, class_logits: torch.Tensor, mask_embed: torch.Tensor) -> torch.Tensor:
        """-> logits (B, K, h, w) on the pixel embedding's grid."""
        if self.kind == "presence":
            return presence_logits(pixel, class_logits, mask_embed)
        return grid_logits(pixel, class_logits.softmax(-1), mask_embed)

    def forward(self, pixel: torch.Tensor, class_logits: torch.Tensor, mask_embed: torch.Tensor,
                out_size: tuple[int, int]) -> torch.Tensor:
        return upsample_logits(self.grid(pixel, class_logits, mask_embed), out_size)


def upsample_logits(grid: torch.Tensor, out_size: tuple[int, int]) -> torch.Tensor:
    """Grid logits (B, K, h, w) -> (B, K, H, W), bilinear: how the network's outputs reach its input size."""
    return F.interpolate(grid, size=out_size, mode="bilinear", align_corners=False)
