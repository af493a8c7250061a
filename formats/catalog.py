"""The names the api and the pipeline agree on: pipeline presets, stage contracts and camera presets, as data.

The api validates a job's preset, its stage list and a sequence's camera against these without importing the
pipeline; the pipeline builds its `PipelineConfig`s and stages (worker.slam.catalog) and `Camera`s
(worker.slam.camera) from the same entries, so there is one list to edit.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from formats.errors import FormatError


@dataclass(frozen=True)
class StageContract:
    """What a per-frame stage reads from the stages before it and what it hands on, by product name (the
    names of `worker.slam.stages.FrameInputs` fields)."""

    name: str
    needs: tuple[str, ...] = ()
    """Products an earlier stage must provide: without them the stage cannot do its job."""
    uses: tuple[str, ...] = ()
    """Products the stage reads when an earlier stage provides them and does without otherwise."""
    provides: tuple[str, ...] = ()


STAGE_CONTRACTS: dict[str, StageContract] = {
    c.name: c for c in (
        StageContract("segmentation", provides=("potentially_dynamic", "class_labels")),
        # Extracts the frame's features itself; with segmentation's mask (and `culling.use_segmentation`,
        # default on) it judges the marked objects, without one it judges geometric clusters alone.
        StageContract("culling", uses=("potentially_dynamic",),
                      provides=("features", "exclude_mask", "dynamic_mask", "held_back", "extracted", "culled")),
        # Fills the pixels judged moving from reference frames; matches them by the kept features' descriptors.
        StageContract("restoration", needs=("dynamic_mask",), uses=("features",),
                      provides=("restored_rgb", "restored_depth", "extra_features", "previews")),
    )
}
"""The shipped stages, in the order they run when all are listed."""


class StageOrderError(FormatError):
    """A stage list the pipeline cannot run; ``detail`` says which stage and why (JSON-able)."""

    def __init__(self, message: str, detail: dict[str, object]) -> None:
        super().__init__(message)
        self.detail = detail


def check_stage_order(stages: Sequence[str], contracts: Mapping[str, StageContract] = STAGE_CONTRACTS) -> None:
    """Refuse (StageOrderError) an unknown stage, one listed twice, one whose `needs` no earlier stage provides
    (restoration alone), and one listed before a stage that provides what it needs or uses (culling after
    restoration, or before segmentation: it would quietly run without the mask)."""
    provided: set[str] = set()
    for i, name in enumerate(stages):
        if name not in contracts:
            raise StageOrderError(f"unknown pipeline stage {name!r}; known: {', '.join(contracts)}",
                                  {"stage": name, "allowed": list(contracts)})
        if name in stages[:i]:
            raise StageOrderError(f"pipeline stage {name!r} is listed twice", {"stage": name, "stages": list(stages)})
        contract = contracts[name]
        later = [s for s in stages[i + 1:] if s in contracts]
        for product in (*contract.needs, *contract.uses):
            late = [s for s in later if product in contracts[s].provides]
            if product not in provided and (late or product in contract.needs):
                verb = "needs" if product in contract.needs else "uses"
                providers = late or [c.name for c in contracts.values() if product in c.provides]
                where = f"{' and '.join(repr(s) for s in late)} provides only after it" if late \
                    else "no earlier stage provides"
                raise StageOrderError(
                    f"pipeline stage {name!r} {verb} {product}, which {where}"
                    + (f"; list {' or '.join(repr(p) for p in providers)} before {name!r}" if providers else ""),
                    {"stage": name, verb: product, "providers": providers, "stages": list(stages)})
        provided.update(contract.provides)


def provided_before(stages: Sequence[str], name: str,
                    contracts: Mapping[str, StageContract] = STAGE_CONTRACTS) -> frozenset[str]:
    """The products the stages listed before `name` provide (all listed ones' when `name` is not listed;
    names without a contract provide nothing)."""
    before = stages[: list(stages).index(name)] if name in stages else stages
    return frozenset(p for s in before if s in contracts for p in contracts[s].provides)


@dataclass(frozen=True)
class PipelinePreset:
    name: str
    description: str
    stages: tuple[str, ...]
    """Per-frame stages run before tracking, in order (names of `STAGE_CONTRACTS`)."""


PIPELINE_PRESETS: tuple[PipelinePreset, ...] = (
    PipelinePreset("full", "VTD-SLAM: MSNET segmentation + adaptive epipolar culling + background restoration "
                   "from reference frames", ("segmentation", "culling", "restoration")),
    PipelinePreset("no-restoration", "MSNET segmentation + adaptive epipolar culling, no background restoration",
                   ("segmentation", "culling")),
    PipelinePreset("geometry-only", "epipolar/depth culling of moving clusters, no segmentation, no restoration",
                   ("culling",)),
    PipelinePreset("orb-only", "ORB-SLAM2-style RGB-D tracking and mapping, no dynamic handling", ()),
)
"""Most complete first."""

DEFAULT_PIPELINE_PRESET = "full"
"""What a run or job uses when it names no preset."""


@dataclass(frozen=True)
class CameraPreset:
    """Pinhole intrinsics of a dataset's RGB-D pair; depth PNG value / `depth_scale` = metres."""

    fx: float
    fy: float
    cx: float
    cy: float
    depth_scale: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    """OpenCV coefficients (k1, k2, p1, p2, k3) of the colour image."""
    width: int = 640
    height: int = 480
    depth_registered: bool = True
    """Depth pixels are registered to the colour pixels (the driver reprojected them: TUM, Bonn); False when the
    dataset ships the depth camera's own images (7-Scenes)."""
    groundtruth_frame: str = "camera"
    """What the dataset's ``groundtruth.txt`` is the pose of: a name of :data:`GROUNDTRUTH_FRAMES`."""


GROUNDTRUTH_FRAMES: dict[str, str] = {
    "camera": "the camera's pose T_WC (TUM RGB-D, 7-Scenes, synthetic sequences)",
    "bonn-marker": "Bonn RGB-D Dynamic's motion-capture marker; the camera is T_ROS · T_gt · T_ROS · T_m "
                   "(the dataset's documented offset)",
}
"""What a sequence's ground truth can be the pose of, by name. RPE is always scored against the camera's ground
truth (a marker's corrected to it); ATE is reported against the raw ground truth (the published convention) and
against the camera's."""
DEFAULT_GROUNDTRUTH_FRAME = "camera"


CAMERA_PRESETS: dict[str, CameraPreset] = {
    # TUM RGB-D (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats): ROS-default registered depth.
    "tum1": CameraPreset(517.3, 516.5, 318.6, 255.3, 5000.0, dist=(0.2624, -0.9531, -0.0054, 0.0026, 1.1633)),
    "tum2": CameraPreset(520.9, 521.0, 325.1, 249.7, 5000.0, dist=(0.2312, -0.7849, -0.0033, -0.0001, 0.9172)),
    "tum3": CameraPreset(535.4, 539.2, 320.1, 247.6, 5000.0),
    # Bonn RGB-D Dynamic (its documented intrinsics; k3 not given).
    # Its ground truth is a motion-capture marker's pose, not the camera's.
    "bonn": CameraPreset(542.822841, 542.576870, 315.593520, 237.756098, 5000.0,
                         dist=(0.039903, -0.099343, -0.000730, -0.000144, 0.0), groundtruth_frame="bonn-marker"),
    # Microsoft 7-Scenes nominal depth intrinsics; depth in millimetres, from the Kinect's depth camera and not
    # registered to colour (the dataset says so): a keypoint's depth may be a neighbouring surface's.
    "7scenes": CameraPreset(585.0, 585.0, 320.0, 240.0, 1000.0, depth_registered=False),
}
