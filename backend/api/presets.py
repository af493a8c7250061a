"""``GET /presets``: the names a client may choose from (pipeline presets for jobs, cameras for uploads)."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, Field

from storage.presets import CAMERA_PRESETS, PIPELINE_PRESETS

router = APIRouter(tags=["presets"])


class Presets(BaseModel):
    pipeline: list[str] = Field(examples=[["orb-only"]])
    camera: list[str] = Field(examples=[["7scenes", "bonn", "tum1", "tum2", "tum3"]])


@router.get("/presets", response_model=Presets)
def list_presets() -> Presets:
    return Presets(pipeline=list(PIPELINE_PRESETS), camera=list(CAMERA_PRESETS))
