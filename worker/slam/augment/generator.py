"""The augmented-real generator: people (or other COCO movers) walking through a real static RGB-D sequence.

The output is a TUM-layout sequence (same timestamps, ground truth, camera and depth scale as the source) with
truth files; the true background of each frame is the source frame itself (its files are copied byte for byte),
or, with static instances (a parked chair that never moves), the source with those pasted in: they belong to
the static scene, so `truth/masks` never marks them. With movers other than people or with static instances,
two more per-frame images lie beside the masks (`truth.json`'s `generator` names them):
`truth/classes/000000.png` (uint8, COCO-80 class id + 1 of every pasted pixel, moving or static; 0 = source)
and `truth/static/000000.png` (uint8 ids of the visible static instances, listed in `generator.static`).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from functools import partial
from pathlib import Path

import cv2
import numpy as np

from worker.slam.augment.composite import Billboard, composite
from worker.slam.augment.floor import Floor, backproject, estimate_floor, gravity_up, world_normals
from worker.slam.augment.movers import (
    COCO80,
    DEFAULT_MOVERS,
    MOVER_CLASSES,
    PERSON,
    MoverClass,
    is_people_only,
    parse_movers,
)
from worker.slam.augment.placement import PlacementConfig, Walk, plan_static, plan_walks
from worker.slam.augment.sprites import Sprite, SpriteFilter, load_sprites
from worker.slam.camera import Camera
from worker.slam.errors import ConfigError, SequenceFormatError
from worker.slam.io.sequence import Sequence
from worker.slam.io.trajectory import Trajectory
from worker.slam.synth.writer import PNG_FAST, SequenceWriter
from worker.slam.truth import TRUTH_DIR


@dataclass(frozen=True)
class AugmentConfig:
    """What to generate."""

    frames: int | None = None
    """Use the first N frames of the source (None = all)."""
    people: int = 2
    """Number of movers (people by default) taking turns to walk through the view."""
    movers: str = DEFAULT_MOVERS
    """Classes pasted: comma-separated groups (person, animal, vehicle, object) or COCO names (`movers.py`)."""
    static: int = 0
    """Instances that stand still for the whole sequence (part of the static scene)."""
    static_classes: str | None = None
    """Their classes, as `movers` (None = the movers' classes)."""
    seed: int = 0
    """Seed of sprite choice, distances, timing."""
    camera: Camera | None = None
    """Intrinsics when the source has no camera.json (e.g. the 7scenes preset)."""
    placement: PlacementConfig = field(default_factory=PlacementConfig)
    """How people walk."""
    sprites: SpriteFilter = field(default_factory=SpriteFilter)
    """Which COCO instances are used."""


@dataclass(frozen=True)
class AugmentedFrame:
    """One composited frame: `rgb` uint8 (H,W,3), `depth` raw uint16 (H,W) in the source's units, `ids` uint8
    (H,W) moving instance ids (0 = static scene), `static_ids` uint8 (H,W) visible static instances' ids,
    `classes` uint8 (H,W) COCO-80 id + 1 of every pasted pixel (0 = source), `background_rgb`/`_depth` the
    static scene alone (the source frame with the static instances)."""

    rgb: np.ndarray
    depth: np.ndarray
    ids: np.ndarray
    static_ids: np.ndarray
    classes: np.ndarray
    background_rgb: np.ndarray
    background_depth: np.ndarray


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
        if n < 1 or cfg.people < 0 or cfg.static < 0 or cfg.people + cfg.static > 255:
            raise ConfigError(f"need at least one frame, people >= 0, static >= 0 and at most 255 instances, got "
                              f"{n}, {cfg.people}, {cfg.static}")
        self.classes = parse_movers(cfg.movers)
        idx, poses = self.seq.groundtruth_for_frames()
        if len(idx) < len(self.seq) or not np.array_equal(idx, np.arange(len(self.seq))):
            raise SequenceFormatError("every frame needs a ground-truth pose to place people in 3D",
                                      path=self.seq.root / "groundtruth.txt")
        self.n, self.poses = n, poses[:n]
        # The movers' sprites first, so people-only walks draw from the same list as they always did.
        self.static_classes = parse_movers(cfg.static_classes) if cfg.static_classes else self.classes
        self.sprites: list[Sprite] = load_sprites(coco_dir, cfg.sprites, tuple(m.coco_id for m in self.classes))
        n_movers = len(self.sprites)
        extra = tuple(m.coco_id for m in self.static_classes if m not in self.classes)
        if extra and cfg.static:
            self.sprites += load_sprites(coco_dir, cfg.sprites, extra)
        for classes, pool in ((self.classes, self.sprites[:n_movers]),
                              (self.static_classes if cfg.static else (), self.sprites)):
            ids = {m.coco_id for m in classes}
            if classes and not any(s.coco_id in ids for s in pool):
                what = "whole-body person" if is_people_only(classes) else ", ".join(m.name for m in classes)
                raise SequenceFormatError(f"no usable {what} instances", path=Path(coco_dir))
        rng = np.random.default_rng(cfg.seed)
        self.floor, centre = self._survey(rng)
        fps = (n - 1) / max(self.seq.timestamps[n - 1] - self.seq.timestamps[0], 1e-9) if n > 1 else 30.0
        self.walks = plan_walks(self.poses, centre, self.floor, self.seq.camera, cfg.people, n_movers, fps, rng,
                                cfg.placement, self._heights,
                                None if is_people_only(self.classes) else partial(self._pick, self.classes))
        # Their own random stream, so adding static instances leaves the walks as they were.
        self.statics = plan_static(self.poses, centre, self.floor, self.seq.camera, cfg.static, cfg.people + 1,
                                   partial(self._pick, self.static_classes), np.random.default_rng([cfg.seed, 1]),
                                   self._heights, cfg.placement)

    def _pick(self, classes: tuple[MoverClass, ...], rng: np.random.Generator) -> int:
        """A sprite index of one of `classes`: a class first (each class with sprites equally likely), then one of
        its sprites, so the class with the most COCO128 instances does not crowd out the others."""
        wanted = {m.coco_id for m in classes}
        by_class: dict[int, list[int]] = {}
        for k, s in enumerate(self.sprites):
            if s.coco_id in wanted:
                by_class.setdefault(s.coco_id, []).append(k)
        members = list(by_class.values())[int(rng.integers(len(by_class)))]
        return members[int(rng.integers(len(members)))]

    def _heights(self, sprite: int) -> tuple[float, float]:
        """Height range (m) of a sprite's class: people as `placement.height_m`, others their real size."""
        cls = self.sprites[sprite].coco_id
        return self.cfg.placement.height_m if cls == PERSON else MOVER_CLASSES[COCO80[cls]].height_m

    @property
    def extras(self) -> bool:
        """Whether the class and static-instance images are written (movers other than people, or static ones)."""
        return self.cfg.static > 0 or not is_people_only(self.classes)

    def class_of(self, w: Walk) -> str:
        """COCO name of the instance a walk (or static instance) pastes."""
        return COCO80[self.sprites[w.sprite].coco_id]

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
        f = self.layers(i)
        return f.rgb, f.depth, f.ids

    def _paste(self, rgb: np.ndarray, depth: np.ndarray, ids: np.ndarray, i: int, walks: list[Walk]) -> None:
        """Composite `walks` active at frame `i`, far to near (a nearer one overwrites a farther one; the depth
        test also holds either way)."""
        T = self.poses[i]
        active = [w for w in walks if w.first <= i <= w.last]
        active.sort(key=lambda w: -np.linalg.norm(w.position(i) - T[:3, 3]))
        for w in active:
            foot = w.position(i) + w.bob(i) * self.floor.up
            # A body rounds 12 cm (a cat less) towards the camera; a static instance stays a flat, rigid plane.
            bulge = 0.0 if w.facing is not None else min(0.12, 0.3 * w.height)
            composite(rgb, depth, ids, self.seq.camera, T, self.floor,
                      Billboard(self.sprites[w.sprite], foot, w.height, bulge, w.facing), w.walker)

    def layers(self, i: int) -> AugmentedFrame:
        """Frame `i` with its truth layers: the static instances pasted into the source (the background), then
        the movers over them."""
        bg_rgb = self.seq[i].rgb.copy()
        bg_depth = cv2.imread(str(self.seq.frames[i].depth_path), cv2.IMREAD_UNCHANGED)
        if bg_depth is None:
            raise SequenceFormatError(f"cannot read depth image {self.seq.frames[i].depth_path.name}")
        static_ids = np.zeros(bg_depth.shape, np.uint8)
        self._paste(bg_rgb, bg_depth, static_ids, i, self.statics)
        rgb, depth = bg_rgb.copy(), bg_depth.copy()
        ids = np.zeros(bg_depth.shape, np.uint8)
        self._paste(rgb, depth, ids, i, self.walks)
        static_ids[ids > 0] = 0  # hidden behind a mover
        classes = np.zeros(bg_depth.shape, np.uint8)
        for layer, walks in ((static_ids, self.statics), (ids, self.walks)):
            for w in walks:
                if w.first <= i <= w.last:
                    classes[layer == w.walker] = self.sprites[w.sprite].coco_id + 1
        return AugmentedFrame(rgb, depth, ids, static_ids, classes, bg_rgb, bg_depth)


def generate_augmented(sequence_dir: Path | str, coco_dir: Path | str, out_dir: Path | str, cfg: AugmentConfig,
                       progress: Callable[[int, int], None] | None = None) -> AugmentResult:
    """Composite movers into the source sequence and write it (TUM layout + truth) into `out_dir`."""
    aug = AugmentedSequence(sequence_dir, coco_dir, cfg)
    out = Path(out_dir)
    if out.resolve() == aug.seq.root.resolve():
        raise ConfigError("the output folder must differ from the source sequence")
    # Backgrounds with static instances are written, not copied: lossless, whatever the source's format.
    ext = ".png" if aug.statics else aug.seq.frames[0].rgb_path.suffix.lower()
    writer = SequenceWriter(out, aug.seq.camera, background_ext=ext)
    if aug.extras:
        for sub in ("classes", "static"):
            (out / TRUTH_DIR / sub).mkdir(parents=True, exist_ok=True)
    fractions = []
    try:
        for i in range(len(aug)):
            f = aug.layers(i)
            ref = aug.seq.frames[i]
            bg = (f.background_rgb, f.background_depth) if aug.statics else (ref.rgb_path, ref.depth_path)
            writer.add(ref.timestamp, f.rgb, f.depth, f.ids, *bg)
            if aug.extras:
                for sub, img in (("classes", f.classes), ("static", f.static_ids)):
                    if not cv2.imwrite(str(out / TRUTH_DIR / sub / f"{i:06d}.png"), img, PNG_FAST):
                        raise OSError(f"could not write {sub} image {i}")
            fractions.append(float((f.ids > 0).mean()))
            if progress:
                progress(i + 1, len(aug))
    except BaseException:
        writer.abort()
        raise
    gt = Trajectory(aug.seq.timestamps[: len(aug)], aug.poses)
    writer.finish(gt, _objects(aug), _info(aug))
    return AugmentResult(out, len(aug), fractions, aug.floor)


def _objects(aug: AugmentedSequence) -> list[dict]:
    """truth.json's moving objects: one per walker id (a walker's walks may paste different classes)."""
    if not aug.extras:
        return [{"id": k + 1, "class": "person", "kind": "COCO billboard"} for k in range(aug.cfg.people)]
    out = []
    for k in range(aug.cfg.people):
        names = sorted({aug.class_of(w) for w in aug.walks if w.walker == k + 1})
        out.append({"id": k + 1, "class": names[0] if len(names) == 1 else "various", "classes": names,
                    "kind": "COCO billboard", "moving": True})
    return out


def _info(aug: AugmentedSequence) -> dict:
    """truth.json's generator entry; the movers' classes and static instances only when the extras exist."""
    cfg = aug.cfg
    walks = [{"walker": w.walker, "sprite": aug.sprites[w.sprite].source, "first": w.first, "last": w.last,
              "height_m": w.height} for w in aug.walks]
    info = {"name": "augment", "source": str(aug.seq.root), "seed": cfg.seed, "people": cfg.people,
            "floor": {"up": aug.floor.up.tolist(), "height": aug.floor.height, "inliers": aug.floor.inliers},
            "walks": walks, "placement": asdict(cfg.placement)}
    if aug.extras:
        for w, d in zip(aug.walks, walks):
            d["class"] = aug.class_of(w)
        info.update({
            "movers": [m.name for m in aug.classes], "movers_spec": cfg.movers,
            "classes_mask": "classes/{index:06d}.png", "static_mask": "static/{index:06d}.png",
            "static_classes": [m.name for m in aug.static_classes],
            "static": [{"id": w.walker, "class": aug.class_of(w), "sprite": aug.sprites[w.sprite].source,
                        "height_m": w.height, "floor_point": w.start.tolist(),
                        "facing": None if w.facing is None else w.facing.tolist()}
                       for w in aug.statics]})
    return info
