"""Small building blocks shared by the MSNET modules."""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def conv_bn_act(c_in: int, c_out: int, kernel: int = 3, stride: int = 1) -> nn.Sequential:
    """Conv + BatchNorm + ReLU; BN folds into the conv at inference so it costs nothing on CPU."""
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, kernel, stride, kernel // 2, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


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
