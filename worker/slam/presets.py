"""Named pipeline presets, and the registration of the shipped stages with their config sections.

The floor above the stages: `config.py` knows no stage and a stage knows no preset. The presets' names,
descriptions and stage lists are `formats.catalog` data (the api reads the same list); this module turns them
into `PipelineConfig`s. Importing it registers the segmentation, culling and restoration stages and sections.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from formats.catalog import DEFAULT_PIPELINE_PRESET, PIPELINE_PRESETS, PipelinePreset
from worker.slam.config import PipelineConfig, register_section
from worker.slam.dynamic.stage import CullingStage, CullingStageConfig, SegmentationStage, SegmentationStageConfig
from worker.slam.errors import ConfigError
from worker.slam.inpainting.stage import RestorationStage, RestorationStageConfig
from worker.slam.stages import register_stage


@dataclass(frozen=True)
class Preset:
    name: str
    description: str
    factory: Callable[[], PipelineConfig]
    """Returns a fresh config on every call."""


_PRESETS: dict[str, Preset] = {}


def register_preset(name: str, factory: Callable[[], PipelineConfig], description: str) -> None:
    """Register (or replace) a named preset. The factory returns a fresh config each call."""
    _PRESETS[name] = Preset(name, description, factory)


def preset_names() -> list[str]:
    return sorted(_PRESETS)


def default_preset() -> str:
    """The preset a run uses when it names none (`formats.catalog.DEFAULT_PIPELINE_PRESET`)."""
    return DEFAULT_PIPELINE_PRESET


def get_preset(name: str, overrides: dict | None = None) -> PipelineConfig:
    if name not in _PRESETS:
        raise ConfigError(f"unknown preset {name!r}; choose one of {preset_names()}")
    cfg = _PRESETS[name].factory()
    cfg.name = name
    return cfg.with_overrides(overrides) if overrides else cfg


def describe_presets() -> dict[str, str]:
    return {n: p.description for n, p in sorted(_PRESETS.items())}


def _factory(spec: PipelinePreset) -> Callable[[], PipelineConfig]:
    def build() -> PipelineConfig:
        return PipelineConfig(name=spec.name, stages=list(spec.stages))

    return build


def _register_shipped() -> None:
    # Section order is the order of a config snapshot's keys (config.json), so it stays fixed.
    register_section("segmentation", SegmentationStageConfig)
    register_section("culling", CullingStageConfig)
    register_section("restoration", RestorationStageConfig)
    for stage in (SegmentationStage, CullingStage, RestorationStage):
        register_stage(stage.name, stage)
    for spec in PIPELINE_PRESETS:
        register_preset(spec.name, _factory(spec), spec.description)


_register_shipped()
