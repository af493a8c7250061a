"""The augmented-real generator: people from COCO walking through a real static RGB-D sequence with GT poses.

The output is a TUM-layout sequence (same timestamps, ground truth, camera and depth scale as the source) with
truth files; the true background of each frame is the source frame itself (its files are copied byte for byte).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from worker.slam.augment.composite import Billboard, composite
from worker.slam.augment.floor import Floor, backproject, estimate_floor, gravity_up, world_normals
from worker.slam.augment.placement import PlacementConfig, plan_walks
from worker.slam.augment.sprites import Sprite, SpriteFilter, load_sprites
from worker.slam.camera import Camera
from worker.slam.errors import ConfigError, SequenceFormatError
from worker.slam.io.sequence import Sequence
from worker.slam.io.trajectory import Trajectory
from worker.slam.synth.writer import SequenceWriter


@dataclass(frozen=True)
class AugmentConfig:
    """What to generate."""

    frames: int | None = None
    """Use the first N frames of the source (None = all)."""
    people: int = 2
    """Number of people taking turns to walk through the view."""
    seed: int = 0
    """Seed of sprite choice, distances, timing."""
    camera: Camera | None = None
    """Intrinsics when the source has no camera.json (e.g. the 7scenes preset)."""
    placement: PlacementConfig = field(default_factory=PlacementConfig)
    """How people walk."""
    sprites: SpriteFilter = field(default_factory=SpriteFilter)
    """Which COCO people are used."""


@dataclass(frozen=True)
class AugmentResult:
    """Where the sequence went; per-frame fraction of the image covered by people."""

    root: Path
    frames: int
    dynamic_fraction: list[float]
    floor: Floor


class AugmentedSequence:
    """Source frames, floor and planned walks; frames are composited on demand."""

    def __init__(self, sequence_dir: Path | str, coco_dir: Path | str, cfg: AugmentConfig) -> None:
        from worker.slam.camera import camera_from_preset

        self.cfg = cfg
        self.seq = Sequence(sequence_dir, cfg.camera or camera_from_preset("7scenes"))
        n = len(self.seq) if cfg.frames is None else min(cfg.frames, len(self.seq))
        if n < 1 or cfg.people < 0:
            raise ConfigError(f"need at least one frame and people >= 0, got {n}, {cfg.people}")
        idx, poses = self.seq.groundtruth_for_frames()
        if len(idx) < len(self.seq) or not np.array_equal(idx, np.arange(len(self.seq))):
            raise SequenceFormatError("every frame needs a ground-truth pose to place people in 3D",
                                      path=self.seq.root / "groundtruth.txt")
        self.n, self.poses = n, poses[:n]
        self.sprites: list[Sprite] = load_sprites(coco_dir, cfg.sprites)
        if not self.sprites:
            raise SequenceFormatError("no usable whole-body person instances", path=Path(coco_dir))
        rng = np.random.default_rng(cfg.seed)
        self.floor, centre = self._survey(rng)
        fps = (n - 1) / max(self.seq.timestamps[n - 1] - self.seq.timestamps[0], 1e-9) if n > 1 else 30.0
        self.walks = plan_walks(self.poses, centre, self.floor, self.seq.camera, cfg.people, len(self.sprites),
                                fps, rng, cfg.placement)

    def _survey(self, rng: np.random.Generator) -> tuple[Floor, np.ndarray]:
        """Gravity and floor plane from ~40 sampled frames and the median central depth of every 5th frame
        (interpolated)."""
        cam = self.seq.camera
        sample = np.unique(np.linspace(0, self.n - 1, min(self.n, 40)).astype(int))
        points, normals, centre_s = [], [], []
        for i in sample:
            depth = self.seq[i].depth
            points.append(backproject(depth, cam, self.poses[i]))
            normals.append(world_normals(depth, cam, self.poses[i]))
            h, w = depth.shape
            mid = depth[h // 4: 3 * h // 4, w // 4: 3 * w // 4]
            centre_s.append(float(np.median(mid[mid > 0])) if (mid > 0).any() else 0.0)
        up = gravity_up(self.poses, np.concatenate(normals))
        floor = estimate_floor(np.concatenate(points), self.poses, up)
        centre = np.interp(np.arange(self.n), sample, centre_s)
        return floor, centre

    def __len__(self) -> int:
        return self.n

    def frame(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(RGB uint8 (H,W,3), raw uint16 depth (H,W) in the source's units, uint8 ids (H,W)) of frame `i`."""
        rgb = self.seq[i].rgb.copy()
        depth = cv2.imread(str(self.seq.frames[i].depth_path), cv2.IMREAD_UNCHANGED)
        if depth is None:
            raise SequenceFormatError(f"cannot read depth image {self.seq.frames[i].depth_path.name}")
        ids = np.zeros(depth.shape, np.uint8)
        T = self.poses[i]
        active = [w for w in self.walks if w.first <= i <= w.last]
        # Far to near, so a nearer person overwrites a farther one (the depth test also holds either way).
        active.sort(key=lambda w: -np.linalg.norm(w.position(i) - T[:3, 3]))
        for w in active:
            foot = w.position(i) + w.bob(i) * self.floor.up
            composite(rgb, depth, ids, self.seq.camera, T, self.floor,
                      Billboard(self.sprites[w.sprite], foot, w.height), w.walker)
        return rgb, depth, ids


def generate_augmented(sequence_dir: Path | str, coco_dir: Path | str, out_dir: Path | str, cfg: AugmentConfig,
                       progress: Callable[[int, int], None] | None = None) -> AugmentResult:
    """Composite people into the source sequence and write it (TUM layout + truth) into `out_dir`."""
    aug = AugmentedSequence(sequence_dir, coco_dir, cfg)
    out = Path(out_dir)
    if out.resolve() == aug.seq.root.resolve():
        raise ConfigError("the output folder must differ from the source sequence")
    ext = aug.seq.frames[0].rgb_path.suffix.lower()
    writer = SequenceWriter(out, aug.seq.camera, background_ext=ext)
    fractions = []
    try:
        for i in range(len(aug)):
            rgb, depth, ids = aug.frame(i)
            ref = aug.seq.frames[i]
            writer.add(ref.timestamp, rgb, depth, ids, ref.rgb_path, ref.depth_path)
            fractions.append(float((ids > 0).mean()))
            if progress:
                progress(i + 1, len(aug))
    except BaseException:
        writer.abort()
        raise
    gt = Trajectory(aug.seq.timestamps[: len(aug)], aug.poses)
    objects = [{"id": k + 1, "class": "person", "kind": "COCO billboard"} for k in range(cfg.people)]
    info = {"name": "augment", "source": str(aug.seq.root), "seed": cfg.seed, "people": cfg.people,
            "floor": {"up": aug.floor.up.tolist(), "height": aug.floor.height, "inliers": aug.floor.inliers},
            "walks": [{"walker": w.walker, "sprite": aug.sprites[w.sprite].source, "first": w.first,
                       "last": w.last, "height_m": w.height} for w in aug.walks],
            "placement": asdict(cfg.placement)}
    writer.finish(gt, objects, info)
    return AugmentResult(out, len(aug), fractions, aug.floor)
