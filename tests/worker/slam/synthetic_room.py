"""A textured box room ray-cast with exact depth, for tests with known poses (no files, no randomness left)."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

HALF = np.array([2.0, 1.5, 2.5])  # room half extents (x, y, z), metres
K_SYN = np.array([[525.0, 0, 319.5], [0, 525.0, 239.5], [0, 0, 1]])
W, H = 640, 480


TEX_PX, TEX_M = 1024, 0.005  # texture pixels per side, metres per texture pixel


def _textures(seed: int = 7) -> list[np.ndarray]:
    """One distinctive float32 texture per face: random filled polygons over smooth noise (no repetition)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(6):
        tex = cv2.GaussianBlur(rng.random((TEX_PX, TEX_PX)).astype(np.float32), (0, 0), 6) * 0.6 + 0.2
        for _ in range(700):  # polygons: real corners that stay put when the viewpoint changes
            c = rng.integers(0, TEX_PX, 2)
            pts = (c + rng.integers(-30, 30, (int(rng.integers(3, 5)), 2))).astype(np.int32)
            cv2.fillPoly(tex, [pts], float(rng.random()), cv2.LINE_AA)
        out.append(tex)
    return out


_TEXTURES = _textures()


def render(T_WC: np.ndarray, K: np.ndarray = K_SYN, w: int = W, h: int = H) -> tuple[np.ndarray, np.ndarray]:
    """RGB uint8 (h,w,3) and depth float32 metres (h,w) of the room seen from camera pose `T_WC`."""
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    d_c = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    d_w = d_c @ T_WC[:3, :3].T
    o = T_WC[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_axes = (np.sign(d_w) * HALF - o) / d_w
    t_axes = np.where(np.isfinite(t_axes) & (t_axes > 0), t_axes, np.inf)
    axis = np.argmin(t_axes, -1)
    t = np.take_along_axis(t_axes, axis[..., None], -1)[..., 0]
    p = o + d_w * t[..., None]
    face = axis * 2 + (np.take_along_axis(d_w, axis[..., None], -1)[..., 0] > 0)
    a_idx = np.where(axis == 0, 1, 0)
    b_idx = np.where(axis == 2, 1, 2)
    a = ((np.take_along_axis(p, a_idx[..., None], -1)[..., 0] + 2.56) / TEX_M).astype(np.float32)
    b = ((np.take_along_axis(p, b_idx[..., None], -1)[..., 0] + 2.56) / TEX_M).astype(np.float32)
    val = np.zeros(t.shape, np.float32)
    for f in range(6):
        m = face == f
        if m.any():
            val[m] = cv2.remap(_TEXTURES[f], a, b, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)[m]
    tint = np.array([[1.0, 0.9, 0.8], [0.8, 1.0, 0.9], [0.9, 0.8, 1.0], [1.0, 1.0, 0.8], [0.8, 0.9, 1.0],
                     [0.9, 1.0, 1.0]])[face]
    rgb = np.clip(20 + 220 * val[..., None] * tint, 0, 255).astype(np.uint8)
    return rgb, t.astype(np.float32)


def pose(position, yaw_deg: float, pitch_deg: float = 0.0) -> np.ndarray:
    """T_WC looking along +z rotated by yaw (about y) and pitch (about x)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("yx", [yaw_deg, pitch_deg], degrees=True).as_matrix()
    T[:3, 3] = position
    return T


def trajectory(n: int, yaw_span_deg: float = 30.0, radius: float = 0.3) -> np.ndarray:
    """(n,4,4) smooth T_WC: a circle of `radius` in x-z while yawing over `yaw_span_deg` and nodding."""
    s = np.linspace(0, 1, n)
    return np.stack([pose([radius * np.sin(2 * np.pi * si), 0.1 * np.sin(4 * np.pi * si),
                           radius * (1 - np.cos(2 * np.pi * si))],
                          yaw_span_deg * si, -15 + 5 * np.sin(2 * np.pi * si)) for si in s])


def write_sequence(folder: Path, poses: np.ndarray, fps: float = 30.0) -> Path:
    """A TUM-layout folder (rgb/, depth/ PNG at scale 5000, rgb.txt, depth.txt, groundtruth.txt, camera.json)."""
    import json

    from worker.slam.io.trajectory import Trajectory, write_tum_trajectory

    (folder / "rgb").mkdir(parents=True, exist_ok=True)
    (folder / "depth").mkdir(exist_ok=True)
    stamps = np.arange(len(poses)) / fps
    rgb_lines, depth_lines = [], []
    for i, (t, T) in enumerate(zip(stamps, poses)):
        rgb, depth = render(T)
        cv2.imwrite(str(folder / f"rgb/{i:05d}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(folder / f"depth/{i:05d}.png"), np.round(depth * 5000).astype(np.uint16))
        rgb_lines.append(f"{t:.6f} rgb/{i:05d}.png")
        depth_lines.append(f"{t:.6f} depth/{i:05d}.png")
    (folder / "rgb.txt").write_text("# rgb\n" + "\n".join(rgb_lines) + "\n")
    (folder / "depth.txt").write_text("# depth\n" + "\n".join(depth_lines) + "\n")
    write_tum_trajectory(folder / "groundtruth.txt", Trajectory(stamps, poses))
    (folder / "camera.json").write_text(json.dumps({"fx": K_SYN[0, 0], "fy": K_SYN[1, 1], "cx": K_SYN[0, 2],
                                                    "cy": K_SYN[1, 2], "depth_scale": 5000.0, "name": "synthetic"}))
    return folder
