"""Tiny TUM-layout folders made in code for reader tests."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def write_sequence(root: Path, n: int = 3, size: tuple[int, int] = (64, 48), depth_dtype=np.uint16,
                   gt: bool = True, dt: float = 1 / 30) -> Path:
    """n frames of `size` (w, h); rgb/depth stamps offset by 5 ms as in real TUM recordings."""
    (root / "rgb").mkdir(parents=True, exist_ok=True)
    (root / "depth").mkdir(exist_ok=True)
    w, h = size
    rgb_lines, depth_lines, gt_lines = ["# rgb"], ["# depth"], ["# gt"]
    rng = np.random.default_rng(0)
    for i in range(n):
        t = 100.0 + i * dt
        cv2.imwrite(str(root / f"rgb/{t:.6f}.png"), rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
        depth = np.full((h, w), 5000 if depth_dtype == np.uint16 else 50, dtype=depth_dtype)
        cv2.imwrite(str(root / f"depth/{t + 0.005:.6f}.png"), depth)
        rgb_lines.append(f"{t:.6f} rgb/{t:.6f}.png")
        depth_lines.append(f"{t + 0.005:.6f} depth/{t + 0.005:.6f}.png")
        gt_lines.append(f"{t:.6f} {i * 0.1} 0 0 0 0 0 1")
    (root / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (root / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    if gt:
        (root / "groundtruth.txt").write_text("\n".join(gt_lines) + "\n")
    return root
