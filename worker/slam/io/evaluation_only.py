"""The real data sets under ../shared/data that are for evaluation only (DATA.md): no training, fine-tuning,
checkpoint selection or statistics on their frames, whatever a config says. Every offline trainer (MSNET, the
ORB vocabulary) refuses them through this one list."""
from __future__ import annotations

from pathlib import Path

EVALUATION_ONLY = ("bonn_crowd_dev", "davis_movers_dev")
"""Folder names under ``{shared}/data``."""


def is_evaluation_only(path: Path) -> bool:
    """True when ``path`` (resolved) lies in one of the evaluation-only data folders."""
    return any(name in path.resolve().parts for name in EVALUATION_ONLY)
