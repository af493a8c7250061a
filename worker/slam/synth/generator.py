"""The synthetic dynamic-sequence generator: a textured room, walking figures, a real or procedural camera path,
a Kinect-like sensor, and exact truth (masks, static background colour and depth) for every frame."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from worker.slam.camera import PRESETS, Camera
from worker.slam.errors import ConfigError
from worker.slam.io.trajectory import Trajectory
from worker.slam.synth.kinect import KinectConfig, KinectSensor
from worker.slam.synth.paths import circle_path, replay_path, room_frame, walk_path
from worker.slam.synth.people import make_walkers
from worker.slam.synth.render import Renderer
from worker.slam.synth.scene import SceneConfig, build_scene
from worker.slam.synth.textures import build_atlas
from worker.slam.synth.writer import SequenceWriter, depth_to_png

TUM_WALKING_XYZ = Path("data/trajectories/tum_fr3_walking_xyz/groundtruth.txt")
SYNTH_CAMERA = replace(PRESETS["tum3"], name="synthetic")


@dataclass(frozen=True)
class SynthConfig:
    """What to generate."""

    frames: int = 300
    """Number of frames."""
    people: int = 2
    """Number of walking figures."""
    trajectory: str = "auto"
    """"auto" (TUM walking_xyz ground truth from `shared_dir` when present, else "walk"), "circle", "walk",
    or a TUM trajectory file (z-up world, floor at z = 0, like the TUM motion-capture frame)."""
    seed: int = 0
    """Seed of textures, furniture jitter, walkers, procedural path and sensor noise."""
    fps: float = 30.0
    """Frame rate of the generated sequence (recorded paths are sub-sampled to it)."""
    shared_dir: Path | None = None
    """Folder holding `data/trajectories/...` (the shared real data); None = never use it."""
    camera: Camera = SYNTH_CAMERA
    """Intrinsics (TUM fr3, depth scale 5000)."""
    scene: SceneConfig = field(default_factory=SceneConfig)
    """Room size relative to the camera path."""
    kinect: KinectConfig = field(default_factory=KinectConfig)
    """Depth sensor model."""


@dataclass(frozen=True)
class SynthFrame:
    """One generated frame. RGB uint8 (H,W,3); depth float32 m (H,W) with noise and holes; `ids` uint8 (H,W)."""

    timestamp: float
    T_WC: np.ndarray
    rgb: np.ndarray
    depth: np.ndarray
    ids: np.ndarray
    background_rgb: np.ndarray
    background_depth: np.ndarray


def resolve_trajectory(cfg: SynthConfig, rng: np.random.Generator) -> tuple[Trajectory, str]:
    """The camera path T_WC and a description of where it came from."""
    kind = cfg.trajectory
    if kind == "auto":
        real = cfg.shared_dir / TUM_WALKING_XYZ if cfg.shared_dir else None
        if real is not None and real.is_file():
            return replay_path(real, cfg.frames, cfg.fps), f"replay:{real}"
        kind = "walk"
    if kind == "circle":
        return circle_path(cfg.frames, rng, cfg.fps), "circle"
    if kind == "walk":
        return walk_path(cfg.frames, rng, cfg.fps), "walk"
    path = Path(kind)
    if not path.is_file():
        raise ConfigError(f"trajectory must be auto, circle, walk or an existing TUM file, got {kind!r}")
    return replay_path(path, cfg.frames, cfg.fps), f"replay:{path}"


class SyntheticWorld:
    """Everything fixed for a sequence (path, room, walkers); frames are rendered on demand."""

    def __init__(self, cfg: SynthConfig) -> None:
        if cfg.frames < 1 or cfg.people < 0 or cfg.people > 20:
            raise ConfigError(f"need frames >= 1 and 0 <= people <= 20, got {cfg.frames}, {cfg.people}")
        self.cfg = cfg
        rng = np.random.default_rng(cfg.seed)
        self.trajectory, self.source = resolve_trajectory(cfg, rng)
        self.T_WR = room_frame(self.trajectory)
        self.T_RW = np.linalg.inv(self.T_WR)
        cam_room = self.trajectory.positions @ self.T_RW[:3, :3].T + self.T_RW[:3, 3]
        self.scene = build_scene(cam_room[:, :2], build_atlas(rng), rng, cfg.scene)
        self.walkers = make_walkers(cfg.people, self.scene.walk_lo, self.scene.walk_hi, rng)
        self.renderer = Renderer(cfg.camera, self.scene)
        self.sensor = KinectSensor(cfg.kinect, (cfg.camera.height, cfg.camera.width))

    def __len__(self) -> int:
        return len(self.trajectory)

    def frame(self, i: int) -> SynthFrame:
        """Render frame `i`; deterministic for a given seed."""
        t = float(self.trajectory.timestamps[i])
        T_WC = self.trajectory.poses[i]
        rel_t = t - float(self.trajectory.timestamps[0])
        out = self.renderer.render(self.T_RW @ T_WC, [w.parts(rel_t) for w in self.walkers])
        noise, speckle = self.sensor.draw(np.random.default_rng([self.cfg.seed, i]))
        grey_bg = cv2.cvtColor(out.static_rgb, cv2.COLOR_RGB2GRAY)
        bg = self.sensor.measure(out.static_depth, noise)
        bg[self.sensor.holes(out.static_depth, grey_bg, speckle)] = 0
        mask = out.ids > 0
        depth = bg.copy()
        if mask.any():
            # Only dynamic pixels are re-measured: the frame equals the background wherever the mask is 0.
            meas = self.sensor.measure(out.depth, noise)
            holes = self.sensor.holes(out.depth, cv2.cvtColor(out.rgb, cv2.COLOR_RGB2GRAY), speckle)
            depth[mask] = np.where(holes, 0, meas)[mask]
        return SynthFrame(t, T_WC, out.rgb, depth, out.ids, out.static_rgb, bg)


@dataclass(frozen=True)
class SynthResult:
    """Where the sequence went and what it holds."""

    root: Path
    frames: int
    trajectory: Trajectory
    source: str
    dynamic_fraction: list[float]
    """Per frame, the fraction of pixels covered by walkers."""


def generate_synthetic(out_dir: Path | str, cfg: SynthConfig,
                       progress: Callable[[int, int], None] | None = None) -> SynthResult:
    """Render and write a whole sequence (TUM layout + truth) into `out_dir`."""
    world = SyntheticWorld(cfg)
    writer = SequenceWriter(out_dir, cfg.camera)
    scale = cfg.camera.depth_scale
    fractions = []
    try:
        for i in range(len(world)):
            f = world.frame(i)
            mask = f.ids > 0
            bg16 = depth_to_png(f.background_depth, scale)
            fr16 = bg16.copy()
            fr16[mask] = depth_to_png(f.depth[mask], scale)
            writer.add(f.timestamp, f.rgb, fr16, f.ids, f.background_rgb, bg16)
            fractions.append(float(mask.mean()))
            if progress:
                progress(i + 1, len(world))
    except BaseException:
        writer.abort()
        raise
    objects = [{"id": k + 1, "class": "person", "kind": "synthetic walker"} for k in range(cfg.people)]
    info = {"name": "synth", "source": world.source, "seed": cfg.seed, "people": cfg.people,
            "T_WR": world.T_WR.tolist(), "kinect": asdict(cfg.kinect)}
    writer.finish(world.trajectory, objects, info)
    return SynthResult(Path(out_dir), len(world), world.trajectory, world.source, fractions)
