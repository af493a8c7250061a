"""Small building blocks shared by the MSNET modules."""
from __future__ import annotations

import copy

import torch
import torch.nn.functional as F
from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval


def conv_bn_act(c_in: int, c_out: int, kernel: int = 3, stride: int = 1) -> nn.Sequential:
    """Conv + BatchNorm + ReLU; BN folds into the conv at inference (`fold_batchnorm`)."""
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, kernel, stride, kernel // 2, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


class Repeat(nn.Module):
    """(B, C, H, W) -> (B, n*C, H, W): the channels repeated n times (channel j*C + c is input channel c)."""

    def __init__(self, n: int) -> None:
        super().__init__()
        self.n = n

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([x] * self.n, dim=1)


def separable_conv_bn_act(c_in: int, c_out: int, rank: int) -> nn.Sequential:
    """A 3x3 conv factorised to rank `rank` per input channel: depthwise 3x3 over `rank` copies of the channels,
    then a 1x1 mixing them (+ BatchNorm + ReLU). The dense kernel W[o, i] (3x3) becomes
    sum_r P[o, r*C + i] * D[r*C + i]. The copies are explicit because PyTorch's depthwise conv with a channel
    multiplier took 10x longer on CPU than a plain one over twice the channels."""
    c_mid = c_in * rank
    return nn.Sequential(
        *([Repeat(rank)] if rank > 1 else []),
        nn.Conv2d(c_mid, c_mid, 3, 1, 1, groups=c_mid, bias=False),
        nn.Conv2d(c_mid, c_out, 1, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


def fold_batchnorm(model: nn.Module) -> nn.Module:
    """An eval-mode copy of `model` with every BatchNorm2d that follows a Conv2d in a Sequential folded into the
    conv's weights and bias (left as Identity): the same function up to float rounding, one pass fewer per
    block (the BN passes were ~4 % of MSNET's CPU time). The original stays trainable."""
    folded = copy.deepcopy(model).eval()
    for seq in folded.modules():
        if isinstance(seq, nn.Sequential):
            for i in range(len(seq) - 1):
                conv, bn = seq[i], seq[i + 1]
                if isinstance(conv, nn.Conv2d) and isinstance(bn, nn.BatchNorm2d):
                    seq[i], seq[i + 1] = fuse_conv_bn_eval(conv, bn), nn.Identity()
    return folded


class Mlp(nn.Module):
    """Linear-GELU-Dropout-Linear, used for the class and mask heads."""

    def __init__(self, dim_in: int, dim_hidden: int, dim_out: int, dropout: float = 0.0) -> None:
        super().__init__()
        self.fc1 = nn.Linear(dim_in, dim_hidden)
        self.fc2 = nn.Linear(dim_hidden, dim_out)
        self.drop = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.fc2(self.drop(F.gelu(self.fc1(x))))


def resize_pos_embed(pos: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Learned position embedding (1, C, h0, w0) resampled to the current grid, so any input size works."""
    if pos.shape[-2:] == size:
        return pos
    return F.interpolate(pos, size=size, mode="bilinear", align_corners=False)
