"""Size and class list of an MSNET model. Sizes are config, not copies of the model code."""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any


@dataclass(frozen=True)
class MsnetConfig:
    """Architecture hyper-parameters. The defaults are the small CPU model shipped in `weights/`."""

    classes: tuple[str, ...] = ("background", "person", "chair")
    """Output classes; index 0 must be the background. One decoder query per class."""
    dynamic_classes: tuple[str, ...] = ("person", "chair")
    """Classes treated as potentially dynamic by the SLAM pipeline (a subset of `classes`)."""
    input_size: tuple[int, int] = (192, 256)
    """(height, width) the image is resized to before the network; 4:3 like TUM / 7-Scenes frames."""
    stem_channels: int = 32
    """Channels of C1, the stride-4 map produced by the convolutional stem."""
    widths: tuple[int, ...] = (64, 96, 128)
    """Channels of C2, C3, C4 (strides 8, 16, 32): one pyramid level per entry."""
    depths: tuple[int, ...] = (1, 2, 2)
    """Self-attention layers of the PEncoder at each level."""
    patch_sizes: tuple[int, ...] = (2, 1, 1)
    """PEncoder patch size per level; >1 shortens the token sequence where the map is large."""
    heads: int = 4
    """Attention heads in the PEncoders and the decoder."""
    mlp_ratio: float = 2.0
    """Hidden width of the Transformer MLPs relative to their input width."""
    embed_dim: int = 96
    """Channels of C5, of the decoder queries and of the pixel embedding the masks are read from."""
    filters_per_class: int = 8
    """Channels of each of the M per-class filters of the feature-enhancement module."""
    decoder_layers: int = 2
    """Transformer decoder layers (queries = one per class, memory = enhanced C5 tokens)."""
    dropout: float = 0.1
    """Dropout in the Transformer blocks (the paper trains with 0.56)."""
    cnn: str = "plain"
    """The pyramid's convolutional path: "plain" = one 3x3 stride-2 conv per level from a two-conv stem (trained
    from scratch), "mobilenetv2" = the four stages of a width-0.5 MobileNetV2 (`msnet.mobilenet`; three levels,
    its weights can start from the Apache-2.0 DeepLabV3 teacher's), the PEncoders at `widths` beside them."""
    class_head: str = "identity"
    """How the decoder's queries (one per class) make the class scores. "identity": each query's distribution over
    the classes, trained to be its own class (the checkpoints up to 2026-12-06: the same for every image).
    "presence": each query's logit that its class is present in the image; a class's mask logits are raised by
    log sigmoid(presence), so an absent class scores low everywhere (trained by a per-image presence loss)."""
    pencoders: bool = True
    """Ablation switch: False drops the PEncoders (the pyramid is its CNN path alone)."""
    enhancement_filters: bool = True
    """Ablation switch: False drops the per-class filters of the feature enhancement."""
    guidance_attention: bool = True
    """Ablation switch: False drops the guidance's channel and spatial attention (C5 goes to the upsampling as is)."""
    decoder: bool = True
    """Ablation switch: False drops the Transformer decoder: the class queries reach the heads unchanged, so the
    masks come from fixed per-class embeddings (a 1x1 classifier) and presence is the same for every image."""
    refine_rank: int = 0
    """The guidance's 3x3 refinement of the stride-4 pixel embedding: 0 = a dense 3x3 conv (about a third of the
    forward on one CPU core), r >= 1 = depthwise 3x3 over r copies of the channels then a 1x1,
    i.e. the dense kernel factorised to rank r per input channel (`blocks.separable_conv_bn_act`; made from a
    dense checkpoint by `vtdslam compress-msnet`)."""

    def __post_init__(self) -> None:
        from worker.slam.errors import ConfigError

        if not self.classes or self.classes[0] != "background":
            raise ConfigError("MSNET classes must start with 'background'", detail={"classes": list(self.classes)})
        if not set(self.dynamic_classes) <= set(self.classes):
            raise ConfigError("dynamic_classes must be a subset of classes",
                              detail={"dynamic_classes": list(self.dynamic_classes)})
        if not len(self.widths) == len(self.depths) == len(self.patch_sizes):
            raise ConfigError("widths, depths and patch_sizes need one entry per pyramid level")
        if any(s % 32 for s in self.input_size):
            raise ConfigError(f"input_size must be multiples of 32, got {self.input_size}")
        if self.cnn not in ("plain", "mobilenetv2"):
            raise ConfigError(f"cnn must be 'plain' or 'mobilenetv2', got {self.cnn!r}")
        if self.cnn == "mobilenetv2" and len(self.widths) != 3:
            raise ConfigError("the mobilenetv2 path has three levels (strides 8, 16, 32): give three widths")
        if not 0 <= self.refine_rank <= 9:  # an input channel's (out, 9) kernel slice has rank <= 9
            raise ConfigError(f"refine_rank must be in [0, 9], got {self.refine_rank}")
        if self.class_head not in ("identity", "presence"):
            raise ConfigError(f"class_head must be 'identity' or 'presence', got {self.class_head!r}")
        if not 0.0 <= self.dropout < 1.0:
            raise ConfigError(f"dropout must be in [0, 1), got {self.dropout}")

    @property
    def num_classes(self) -> int:
        return len(self.classes)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> MsnetConfig:
        """Inverse of `to_dict`; lists become tuples and unknown keys are rejected."""
        from worker.slam.errors import ConfigError

        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ConfigError(f"unknown MSNET config keys: {sorted(unknown)}")
        values: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**values)


def default_config() -> MsnetConfig:
    """The shipped CPU model."""
    return MsnetConfig()


