"""Named pipeline presets, read from the shipped catalog (`worker.slam.catalog.shipped_catalog`).

Thin functions for the many callers that want a shipped preset's config; each builds the catalog it reads, so
there is no module state. The presets' names, descriptions and stage lists are `formats.catalog` data (the api
reads the same list).
"""
from __future__ import annotations

from formats.catalog import DEFAULT_PIPELINE_PRESET
from worker.slam.catalog import shipped_catalog
from worker.slam.config import PipelineConfig


def preset_names() -> list[str]:
    return shipped_catalog().preset_names()


def default_preset() -> str:
    """The preset a run uses when it names none (`formats.catalog.DEFAULT_PIPELINE_PRESET`)."""
    return DEFAULT_PIPELINE_PRESET


def get_preset(name: str, overrides: dict | None = None) -> PipelineConfig:
    """A fresh config of the shipped preset `name`, with `overrides` applied (ConfigError if unknown)."""
    return shipped_catalog().preset(name, overrides)


def describe_presets() -> dict[str, str]:
    return shipped_catalog().describe_presets()
