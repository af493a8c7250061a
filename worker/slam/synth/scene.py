"""The static room: an axis-aligned box seen from inside, furniture boxes against its walls, their textures.

Everything is in the *room frame*: z up, floor at z = 0, +y the camera's mean viewing direction. Faces carry a
texture cell and a constant Lambert shade; the renderer looks them up by face id.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from worker.slam.synth.textures import TextureAtlas

LIGHT_DIR = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])


@dataclass(frozen=True)
class SceneConfig:
    """Room size relative to the camera path, in metres."""

    height: float = 2.7
    """Ceiling height above the floor."""
    side_margin: float = 2.4
    """Free space left and right of the camera path."""
    behind: float = 1.2
    """Wall distance behind the rearmost camera position."""
    ahead: float = 4.3
    """Wall distance in front of the foremost camera position (Kinect range ends near 5 m)."""


@dataclass(frozen=True)
class Box:
    """Axis-aligned box `lo`..`hi` (3,) metres, one texture for all faces."""

    lo: np.ndarray
    hi: np.ndarray
    texture: str


@dataclass
class StaticScene:
    """Room interior `room_lo`..`room_hi` plus furniture. Face tables are indexed by face id:
    room faces 0..5 = 2*axis + (hi side), box b faces 6 + 6b + 2*axis + (hi side)."""

    room_lo: np.ndarray
    room_hi: np.ndarray
    boxes: list[Box]
    atlas: TextureAtlas
    walk_lo: np.ndarray
    """(2,) x, y corner of the free floor area where people may walk."""
    walk_hi: np.ndarray
    """(2,) opposite corner of that area."""
    face_cell: np.ndarray = field(init=False)
    """(F, 5) float32: atlas x0, y0, w, h and texels per metre of each face's texture."""
    face_shade: np.ndarray = field(init=False)
    """(F,) float32 Lambert factor of each face."""

    def __post_init__(self) -> None:
        room_tex = ["wall0", "wall1", "wall2", "wall3", "floor", "ceiling"]  # by room face id
        cells, shades = [], []
        for f in range(6 + 6 * len(self.boxes)):
            axis, hi = (f % 6) // 2, (f % 6) % 2
            if f < 6:
                name = room_tex[f]
                normal_sign = -1.0 if hi else 1.0  # room faces look inwards
            else:
                name = self.boxes[(f - 6) // 6].texture
                normal_sign = 1.0 if hi else -1.0
            c = self.atlas.cells[name]
            cells.append((c.x0, c.y0, c.w, c.h, c.texels_per_m))
            shades.append(0.62 + 0.38 * max(0.0, normal_sign * LIGHT_DIR[axis]) + (0.08 if axis == 2 else 0.0))
        self.face_cell = np.asarray(cells, np.float32)
        self.face_shade = np.asarray(shades, np.float32)


def _box(lo, hi, texture: str) -> Box:
    return Box(np.asarray(lo, float), np.asarray(hi, float), texture)


def build_scene(cam_xy: np.ndarray, atlas: TextureAtlas, rng: np.random.Generator,
                cfg: SceneConfig = SceneConfig()) -> StaticScene:
    """A furnished room around camera positions `cam_xy` (N, 2), room frame. Furniture stays by the walls so
    the middle of the room is free for walkers."""
    lo = np.array([cam_xy[:, 0].min() - cfg.side_margin, cam_xy[:, 1].min() - cfg.behind, 0.0])
    hi = np.array([cam_xy[:, 0].max() + cfg.side_margin, cam_xy[:, 1].max() + cfg.ahead, cfg.height])
    xl, xr, yb, yf = lo[0], hi[0], lo[1], hi[1]
    j = lambda s: float(rng.uniform(-s, s))  # noqa: E731  small random shifts per seed
    boxes = [
        _box((-1.3 + j(0.3), yf - 0.7, 0), (0.5 + j(0.3), yf, 0.78), "furn0"),          # desk at the far wall
        _box((-0.9 + j(0.2), yf - 0.45, 0.78), (-0.2 + j(0.1), yf - 0.38, 1.2), "dark"),  # monitor on it
        _box((xr - 0.5, yf - 1.9 + j(0.2), 0), (xr, yf - 0.5, 1.95), "furn1"),           # tall shelf
        _box((xl, yf - 2.6 + j(0.3), 0), (xl + 0.55, yf - 1.2, 1.05), "furn2"),          # side cabinet
        _box((xl + 0.2, yf - 0.8, 0), (xl + 1.1, yf - 0.2, 0.55), "furn3"),              # low chest
        _box((xl + 0.8, yb + 0.3, 0), (xl + 2.0, yb + 1.1, 0.012), "dark"),              # dark rug
        _box((xr - 0.45, yb + 0.2, 0), (xr, yb + 1.3 + j(0.2), 0.9), "furn3"),           # rear sideboard
    ]
    walk_lo = np.array([xl + 1.0, cam_xy[:, 1].max() + 1.2])
    walk_hi = np.array([xr - 0.9, yf - 1.0])
    return StaticScene(lo, hi, boxes, atlas, walk_lo, walk_hi)
