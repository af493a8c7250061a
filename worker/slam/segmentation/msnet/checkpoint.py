"""Saving and loading MSNET checkpoints: config + weights + free-form metadata in one torch file."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import torch

from worker.slam.errors import ConfigError
from worker.slam.segmentation.msnet.config import MsnetConfig
from worker.slam.segmentation.msnet.model import MSNet, build_msnet

FORMAT = "msnet-v1"


def default_checkpoint() -> Path:
    """The checkpoint shipped with the package (trained by `vtdslam train-msnet`, see weights/MODEL_CARD.md)."""
    return Path(__file__).resolve().parents[1] / "weights" / "msnet_default.pt"


def save_model(path: Path, model: MSNet, meta: dict | None = None) -> None:
    """Weights only (no optimiser state): what is shipped and loaded for inference."""
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    tmp = path.with_suffix(".tmp")
    torch.save({"format": FORMAT, "config": model.cfg.to_dict(), "state_dict": state, "meta": meta or {}}, tmp)
    tmp.replace(path)  # atomic: a reader never sees a half-written file


def load_model(path: Path | None = None, device: str | torch.device = "cpu") -> tuple[MSNet, dict]:
    """(model in eval mode on `device`, metadata). Raises ConfigError for a missing or foreign file."""
    path = Path(path) if path is not None else default_checkpoint()
    if not path.is_file():
        raise ConfigError(f"MSNET checkpoint not found: {path}", detail={"path": str(path)})
    data = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ConfigError(f"{path} is not an MSNET checkpoint ({FORMAT})", detail={"path": str(path)})
    model = build_msnet(MsnetConfig.from_dict(data["config"]))
    model.load_state_dict(data["state_dict"])
    return model.to(device).eval(), data.get("meta", {})


def export_model(src: Path, dest: Path, dynamic_classes: tuple[str, ...] | None = None, note: str = "") -> dict:
    """Copy a trained checkpoint to `dest` (e.g. the shipped `msnet_default.pt`), optionally narrowing the classes
    the SLAM pipeline treats as potentially dynamic: a class the network still predicts but that has not earned
    its place (held-out IoU too low) is then left to the static scene. Returns the written metadata."""
    model, meta = load_model(src)
    if dynamic_classes is not None:
        model.cfg = replace(model.cfg, dynamic_classes=tuple(dynamic_classes))  # validated by MsnetConfig
    meta = {**meta, "exported_from": str(src), **({"export_note": note} if note else {})}
    save_model(dest, model, meta)
    return meta
