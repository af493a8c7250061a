"""MSNET training loss: hard-label CE + teacher soft-label CE + the class head's loss (query identity, or per-image
class presence)."""
from __future__ import annotations

import torch
import torch.nn.functional as F

from worker.slam.segmentation.msnet.model import MsnetOutput

#: A class counts as present in a training image when it covers this share of the labelled pixels (hard label or
#: the teacher's argmax): about 100 pixels of the 192x256 input, below that a mask is noise.
PRESENCE_MIN_SHARE = 0.002


def presence_targets(hard: torch.Tensor, soft: torch.Tensor, kd_mask: torch.Tensor, num_classes: int
                     ) -> torch.Tensor:
    """(B, K) float 0/1: class k is present in image b by its hard labels or by the teacher's argmax."""
    b = hard.shape[0]
    valid = hard != 255
    counts = torch.zeros(b, num_classes, device=hard.device)
    counts.scatter_add_(1, torch.where(valid, hard, 0).flatten(1), valid.flatten(1).float())
    teacher = torch.zeros_like(counts)
    teacher.scatter_add_(1, soft.argmax(1).flatten(1), kd_mask.flatten(1))
    share = torch.maximum(counts, teacher) / float(hard[0].numel())
    return (share >= PRESENCE_MIN_SHARE).float()


def msnet_loss(out: MsnetOutput, hard: torch.Tensor, soft: torch.Tensor, kd_mask: torch.Tensor,
               class_weights: torch.Tensor, kd_weight: float, query_weight: float,
               ) -> tuple[torch.Tensor, dict[str, float]]:
    """out.logits (B, K, H, W); hard (B, H, W) int64 with 255 = ignore; soft (B, K, H, W) probabilities;
    kd_mask (B, H, W) in {0, 1}. `query_weight` weighs the class head's loss. Returns (total, parts for logging)."""
    logp = F.log_softmax(out.logits, dim=1)
    ce = F.nll_loss(logp, hard, weight=class_weights, ignore_index=255) if (hard != 255).any() \
        else logp.sum() * 0.0
    kd = (-(soft * logp).sum(1) * kd_mask).sum() / kd_mask.sum().clamp_min(1.0)
    if out.class_logits.ndim == 2:  # presence head: (B, K) logits, the background's unused
        k = out.class_logits.shape[1]
        target = presence_targets(hard, soft, kd_mask, k)
        query = F.binary_cross_entropy_with_logits(out.class_logits[:, 1:], target[:, 1:])
    else:
        b, m, _ = out.class_logits.shape
        query = F.cross_entropy(out.class_logits.reshape(b * m, m), torch.arange(m, device=hard.device).repeat(b))
    total = ce + kd_weight * kd + query_weight * query
    return total, {"loss": total.item(), "ce": ce.item(), "kd": kd.item(), "query": query.item()}
