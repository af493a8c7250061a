"""MSNET training loss: hard-label CE + teacher soft-label CE + the query-identity loss of the class head."""
from __future__ import annotations

import torch
import torch.nn.functional as F

from worker.slam.segmentation.msnet.model import MsnetOutput


def msnet_loss(out: MsnetOutput, hard: torch.Tensor, soft: torch.Tensor, kd_mask: torch.Tensor,
               class_weights: torch.Tensor, kd_weight: float, query_weight: float,
               ) -> tuple[torch.Tensor, dict[str, float]]:
    """out.logits (B, K, H, W); hard (B, H, W) int64 with 255 = ignore; soft (B, K, H, W) probabilities;
    kd_mask (B, H, W) in {0, 1}. Returns (total, parts for logging)."""
    logp = F.log_softmax(out.logits, dim=1)
    ce = F.nll_loss(logp, hard, weight=class_weights, ignore_index=255) if (hard != 255).any() \
        else logp.sum() * 0.0
    kd = (-(soft * logp).sum(1) * kd_mask).sum() / kd_mask.sum().clamp_min(1.0)
    b, m, _ = out.class_logits.shape
    target = torch.arange(m, device=hard.device).repeat(b)
    query = F.cross_entropy(out.class_logits.reshape(b * m, m), target)
    total = ce + kd_weight * kd + query_weight * query
    return total, {"loss": total.item(), "ce": ce.item(), "kd": kd.item(), "query": query.item()}
