"""A textured fronto-parallel wall rendered exactly from any camera pose (ray-plane intersection)."""
from __future__ import annotations

import cv2
import numpy as np

K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
H, W = 240, 320
WALL_Z = 2.0


def texture(seed: int = 0, size: int = 1024) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tex = cv2.resize(rng.integers(0, 255, (size // 8, size // 8, 3), dtype=np.uint8), (size, size),
                     interpolation=cv2.INTER_CUBIC)
    return cv2.GaussianBlur(tex, (5, 5), 1.0)


def pose(tx: float = 0.0, ty: float = 0.0, yaw_deg: float = 0.0) -> np.ndarray:
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    T[:3, 3] = [tx, ty, 0]
    return T


def render(T_WC: np.ndarray, tex: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RGB uint8 (H, W, 3) and depth float32 (H, W) of the wall z = WALL_Z (world), 1 texel = 2 mm."""
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([(xs - K[0, 2]) / K[0, 0], (ys - K[1, 2]) / K[1, 1], np.ones_like(xs)], -1)
    d_w = rays @ T_WC[:3, :3].T
    o = T_WC[:3, 3]
    s = (WALL_Z - o[2]) / d_w[..., 2]
    P = o + s[..., None] * d_w
    u = (P[..., 0] / 0.002 + tex.shape[1] / 2).astype(np.float32)
    v = (P[..., 1] / 0.002 + tex.shape[0] / 2).astype(np.float32)
    rgb = cv2.remap(tex, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    depth = (s * rays[..., 2]).astype(np.float32)  # z in the camera frame
    return rgb, depth


def psnr(a: np.ndarray, b: np.ndarray, m: np.ndarray) -> float:
    """PSNR (dB) of uint8 images `a` against `b` over the bool mask `m`."""
    mse = np.mean((a[m].astype(float) - b[m].astype(float)) ** 2)
    return float(10 * np.log10(255**2 / max(mse, 1e-9)))


def person_hole(h: int = H, w: int = W, frac_w: float = 0.12, frac_h: float = 0.42) -> np.ndarray:
    """A person-like upright ellipse at the image centre, bool (h, w)."""
    m = np.zeros((h, w), np.uint8)
    cv2.ellipse(m, (w // 2, h // 2), (int(w * frac_w), int(h * frac_h)), 0, 0, 360, 1, -1)
    return m.astype(bool)
