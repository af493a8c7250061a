"""A slanted textured wall with a textured board ("a person") in front, rendered exactly from any pose.

The wall is slanted and bumpy so that the static scene has real depth structure: with only two planar layers
a camera motion could explain a moving board (a degenerate test).
"""
from __future__ import annotations

import cv2
import numpy as np

from tests.worker.slam.inpainting.scene import WALL_Z, H, K, W, pose, texture

BOARD_Z = 1.2
BOARD_W, BOARD_H = 0.35, 0.9


def wall_z(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return WALL_Z + 0.4 * x + 0.15 * np.sin(4 * x) + 0.1 * np.cos(5 * y)


def render(T_WC: np.ndarray, board_x: float, wall_tex: np.ndarray, board_tex: np.ndarray):
    """RGB uint8 (H, W, 3), depth float32 (H, W) and the board's mask (H, W) bool."""
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([(xs - K[0, 2]) / K[0, 0], (ys - K[1, 2]) / K[1, 1], np.ones_like(xs)], -1)
    d = rays @ T_WC[:3, :3].T
    o = T_WC[:3, 3]
    out_rgb = np.zeros((H, W, 3), np.uint8)
    depth = np.zeros((H, W), np.float32)
    s_wall = (WALL_Z - o[2]) / d[..., 2]
    for _ in range(8):  # fixed-point ray cast against the bumpy wall z = g(x, y)
        P = o + s_wall[..., None] * d
        s_wall = (wall_z(P[..., 0], P[..., 1]) - o[2]) / d[..., 2]
    s_board = (BOARD_Z - o[2]) / d[..., 2]
    Pb = o + s_board[..., None] * d
    on_board = (np.abs(Pb[..., 0] - board_x) < BOARD_W / 2) & (np.abs(Pb[..., 1]) < BOARD_H / 2)
    for s, tex, sel, offx in ((s_wall, wall_tex, ~on_board, 0.0), (s_board, board_tex, on_board, board_x)):
        P = o + s[..., None] * d
        u = ((P[..., 0] - offx) / 0.002 + tex.shape[1] / 2).astype(np.float32)
        v = (P[..., 1] / 0.002 + tex.shape[0] / 2).astype(np.float32)
        img = cv2.remap(tex, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        out_rgb[sel] = img[sel]
        depth[sel] = (s * rays[..., 2])[sel]
    return out_rgb, depth, on_board


def orb(rgb: np.ndarray, n: int = 1500) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) keypoint positions and their (N, 32) ORB descriptors."""
    kps, desc = cv2.ORB.create(n).detectAndCompute(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), None)
    return np.array([k.pt for k in kps], np.float64).reshape(-1, 2), desc


__all__ = ["K", "H", "W", "pose", "texture", "render", "orb"]
