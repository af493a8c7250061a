"""MobileNetV2 at width 0.5: the convolutional path of the dual pyramid when `MsnetConfig.cnn` is "mobilenetv2".

Its layout is the one inside the Apache-2.0 DeepLabV3 teacher (`deeplabv3_257_mv_gpu.tflite`), so training can
start from those weights (`pretrained_state_dict`; BatchNorm is folded there, hence conv + bias, no BN here).
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

STEM = 16
"""Channels of the first 3x3 stride-2 conv."""
BLOCKS: tuple[tuple[int, int, int], ...] = (
    (16, 8, 1),  # block 0: no expansion (its "expand" entry is the depthwise width)
    (48, 12, 2), (72, 12, 1),
    (72, 16, 2), (96, 16, 1), (96, 16, 1),
    (96, 32, 2), (192, 32, 1), (192, 32, 1), (192, 32, 1), (192, 48, 1), (288, 48, 1), (288, 48, 1),
    (288, 80, 2), (480, 80, 1), (480, 80, 1), (480, 160, 1),
)
"""(expanded channels, output channels, ImageNet stride) of each inverted-residual block."""
STAGE_ENDS = (4, 7, 14, 18)
"""Where strides 4, 8, 16 and 32 end in the layer list (layer 0 is the stem conv, layer i + 1 block i)."""
STAGE_CHANNELS = (12, 16, 48, 160)
"""Output channels of the four stages."""


class InvertedResidual(nn.Module):
    """1x1 expand (absent in block 0) -> 3x3 depthwise (stride, dilation) -> 1x1 linear project; ReLU6; identity
    shortcut when the shape is kept."""

    def __init__(self, c_in: int, c_mid: int, c_out: int, stride: int, dilation: int, expand: bool) -> None:
        super().__init__()
        self.expand = nn.Conv2d(c_in, c_mid, 1) if expand else None
        self.depthwise = nn.Conv2d(c_mid, c_mid, 3, stride, dilation, dilation, groups=c_mid)
        self.project = nn.Conv2d(c_mid, c_out, 1)
        self.residual = stride == 1 and c_in == c_out
        self.act = nn.ReLU6(inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.act(self.expand(x)) if self.expand is not None else x
        y = self.project(self.act(self.depthwise(y)))
        return x + y if self.residual else y


def stages(output_stride: int = 32) -> nn.ModuleList:
    """The stem conv and the 17 blocks (`BLOCKS`) as four stages ending at strides 4, 8, 16, 32 (`STAGE_ENDS`). Past
    `output_stride` the strides become dilations, as DeepLab builds it (the teacher uses 8; the pyramid 32)."""
    stem = nn.Sequential(nn.Conv2d(3, STEM, 3, 2, 1), nn.ReLU6(inplace=True))
    out: list[nn.Module] = [stem]
    current, rate, c_in = 2, 1, STEM
    for i, (c_mid, c_out, stride) in enumerate(BLOCKS):
        if current >= output_stride:
            layer_stride, layer_rate, rate = 1, rate, rate * stride
        else:
            layer_stride, layer_rate, current = stride, 1, current * stride
        out.append(InvertedResidual(c_in, c_mid, c_out, layer_stride, layer_rate, expand=i > 0))
        c_in = c_out
    starts = (0, *STAGE_ENDS[:-1])
    return nn.ModuleList(nn.Sequential(*out[a:b]) for a, b in zip(starts, STAGE_ENDS))


def _conv(weight: np.ndarray, depthwise: bool = False) -> torch.Tensor:
    """TFLite conv kernels are (out, kh, kw, in), depthwise ones (1, kh, kw, channels) -> PyTorch's layout."""
    return torch.from_numpy(np.ascontiguousarray(weight.transpose((3, 0, 1, 2) if depthwise else (0, 3, 1, 2))))


def pretrained_state_dict(tensors: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    """State dict for `stages()` from the teacher's tensors (name -> array, `tflite_teacher.read_constants`).
    Raises KeyError naming a missing tensor."""
    scope = "MobilenetV2"
    flat = {"0.0.weight": _conv(tensors[f"{scope}/Conv/weights"]),
            "0.0.bias": torch.from_numpy(tensors[f"{scope}/Conv/Conv2D_bias"].copy())}
    for i in range(len(BLOCKS)):
        block = f"{scope}/expanded_conv" + (f"_{i}" if i else "")
        parts = (("expand", "weights", "Conv2D_bias"), ("depthwise", "depthwise_weights", "depthwise_bias"),
                 ("project", "weights", "Conv2D_bias"))
        for name, weight, bias in parts[1:] if i == 0 else parts:
            flat[f"{i + 1}.{name}.weight"] = _conv(tensors[f"{block}/{name}/{weight}"], name == "depthwise")
            flat[f"{i + 1}.{name}.bias"] = torch.from_numpy(tensors[f"{block}/{name}/{bias}"].copy())
    return {_staged(key): value for key, value in flat.items()}


def _staged(key: str) -> str:
    """Layer-list key "L.rest" -> stage key "S.j.rest" (layer L is entry j of stage S)."""
    layer, rest = key.split(".", 1)
    index = int(layer)
    stage = next(s for s, end in enumerate(STAGE_ENDS) if index < end)
    return f"{stage}.{index - (0, *STAGE_ENDS)[stage]}.{rest}"
