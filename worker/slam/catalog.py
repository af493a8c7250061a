"""The pipeline's catalog: stage config sections, stages and presets by name, as one explicit value.

Nothing is registered by importing a module: `shipped_catalog()` builds the catalog of the shipped stages
(segmentation, culling, restoration) and the `formats.catalog` presets, and whoever builds configs or stages
takes it (a test builds its own with `dataclasses.replace`). The floor above the stages: `config.py` knows no
stage and a stage knows no catalog.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from formats.catalog import PIPELINE_PRESETS, PipelinePreset, StageContract, StageOrderError, check_stage_order
from formats.version import PROVENANCE_KEYS
from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig
from worker.slam.dynamic.stage import CullingStage, CullingStageConfig
from worker.slam.errors import ConfigError
from worker.slam.inpainting.stage import RestorationStage, RestorationStageConfig
from worker.slam.segmentation.stage import SegmentationStage, SegmentationStageConfig
from worker.slam.stages import FrameStage, StageFactory


@dataclass(frozen=True)
class CatalogStage:
    contract: StageContract
    """Its name, what it needs from earlier stages and what it provides."""
    factory: StageFactory


@dataclass(frozen=True)
class Catalog:
    sections: Mapping[str, type]
    """Stage config sections (dataclasses with defaults) by name, in the order of a snapshot's keys after the
    core sections (config.json)."""
    stages: Mapping[str, CatalogStage]
    """By the name a config lists in `config.stages`."""
    presets: Mapping[str, PipelinePreset]

    def base_config(self) -> PipelineConfig:
        """The default config, carrying every section of the catalog (no stages)."""
        return PipelineConfig.with_sections(self.sections)

    def config_from_dict(self, d: dict) -> PipelineConfig:
        """A config from a (possibly partial) snapshot, e.g. a run's config.json; missing values are defaults. The
        code's ``version`` and ``commit`` a run's config.json carries (`formats.version`) are not config: skipped."""
        d = {k: v for k, v in d.items() if k not in PROVENANCE_KEYS}
        return PipelineConfig.from_dict(d, base=self.base_config())

    def preset(self, name: str, overrides: dict | None = None) -> PipelineConfig:
        """A fresh config of the named preset, with `overrides` (nested or dotted keys) applied; a stage list
        the pipeline could not run is refused here already (`check_order`), before any frame is read."""
        if name not in self.presets:
            raise ConfigError(f"unknown preset {name!r}; choose one of {self.preset_names()}")
        cfg = self.base_config()
        cfg.name, cfg.stages = name, list(self.presets[name].stages)
        cfg = cfg.with_overrides(overrides) if overrides else cfg
        self.check_order(cfg.stages)
        return cfg

    def preset_names(self) -> list[str]:
        return sorted(self.presets)

    def describe_presets(self) -> dict[str, str]:
        return {n: p.description for n, p in sorted(self.presets.items())}

    def check_order(self, stages: list[str]) -> None:
        """ConfigError unless every stage is known, listed once, and gets what it needs from earlier ones."""
        try:
            check_stage_order(stages, {n: s.contract for n, s in self.stages.items()})
        except StageOrderError as exc:
            raise ConfigError(exc.message) from exc

    def build_stages(self, config: PipelineConfig, camera: Camera) -> list[FrameStage]:
        """The stages `config.stages` names, in order, after `check_order`."""
        self.check_order(config.stages)
        return [self.stages[s].factory(config, camera) for s in config.stages]


def shipped_catalog() -> Catalog:
    """The shipped stages with their sections (segmentation, culling, restoration: config.json's key order)
    and the `formats.catalog` presets. Cheap: built anew on each call, so nobody shares a mutable value."""
    stage_classes = (SegmentationStage, CullingStage, RestorationStage)
    sections = {"segmentation": SegmentationStageConfig, "culling": CullingStageConfig,
                "restoration": RestorationStageConfig}
    return Catalog(sections=sections,
                   stages={cls.name: CatalogStage(cls.contract, cls) for cls in stage_classes},
                   presets={p.name: p for p in PIPELINE_PRESETS})
