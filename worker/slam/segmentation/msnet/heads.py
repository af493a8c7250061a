"""Segmentation head: the pixel embedding is multiplied by the mask head (one mask per query), the masks by the
class head (each query's class distribution), then upsampled to the network's input size."""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def grid_logits(pixel: torch.Tensor, class_probs: torch.Tensor, mask_embed: torch.Tensor) -> torch.Tensor:
    """(pixel embedding (B, D, h, w), class distributions (B, Q, K), mask embeddings (B, Q, D)) -> logits
    (B, K, h, w) on the embedding's grid, before the upsampling."""
    # Scaled dot product keeps mask logits O(1) at init whatever the embedding width.
    masks = torch.einsum("bqd,bdhw->bqhw", mask_embed, pixel) / pixel.shape[1] ** 0.5
    # Linear in the masks, so the result is a logit map usable with cross-entropy directly.
    return torch.einsum("bqk,bqhw->bkhw", class_probs, masks)


class ClassMaskHead(nn.Module):
    """(pixel embedding (B, D, h, w), class logits (B, Q, K), mask embeddings (B, Q, D)) -> logits (B, K, H, W)."""

    def forward(self, pixel: torch.Tensor, class_logits: torch.Tensor, mask_embed: torch.Tensor,
                out_size: tuple[int, int]) -> torch.Tensor:
        logits = grid_logits(pixel, class_logits.softmax(-1), mask_embed)
        return F.interpolate(logits, size=out_size, mode="bilinear", align_corners=False)
