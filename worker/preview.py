"""A preview image of a finished run: the estimated trajectory seen from above (x-z plane, TUM camera
convention: y down), keyframes marked. Shown by the dashboard before the 3D viewer loads."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from formats import artifacts
from formats.trajectory import parse_tum_trajectory

SIZE = 480
MARGIN = 30


def _read_xyz(path: Path) -> np.ndarray:
    """(N, 3) camera positions of a TUM trajectory file; empty when there is no file or no pose. A malformed
    file raises formats' FormatError."""
    if not path.is_file():
        return np.zeros((0, 3))
    return parse_tum_trajectory(path.read_text(encoding="utf-8", errors="replace"), path).positions


def write_trajectory_preview(out_dir: Path, name: str = artifacts.PREVIEW) -> Path | None:
    """Draw the trajectory (and keyframes) of ``out_dir`` into ``out_dir/name``; None with under two poses."""
    import cv2

    traj = _read_xyz(out_dir / artifacts.TRAJECTORY)
    if len(traj) < 2:
        return None
    kfs = _read_xyz(out_dir / artifacts.KEYFRAMES)
    xz = traj[:, [0, 2]]
    lo, hi = xz.min(axis=0), xz.max(axis=0)
    scale = (SIZE - 2 * MARGIN) / max(float((hi - lo).max()), 1e-6)
    centre = (lo + hi) / 2

    def px(p: np.ndarray) -> np.ndarray:
        q = (p - centre) * scale + SIZE / 2
        return np.stack([q[:, 0], SIZE - q[:, 1]], axis=1).round().astype(np.int32)  # z up on the image

    img = np.full((SIZE, SIZE, 3), 255, np.uint8)
    cv2.polylines(img, [px(xz).reshape(-1, 1, 2)], False, (40, 110, 230), 2, cv2.LINE_AA)
    for p in px(kfs[:, [0, 2]]) if len(kfs) else []:
        cv2.circle(img, (int(p[0]), int(p[1])), 3, (30, 30, 30), -1, cv2.LINE_AA)
    start = px(xz[:1])[0]
    cv2.circle(img, (int(start[0]), int(start[1])), 6, (60, 170, 60), -1, cv2.LINE_AA)
    span = float((hi - lo).max())
    cv2.putText(img, f"top view (x-z), span {span:.2f} m, {len(traj)} poses", (10, SIZE - 10),
                cv2.FONT_HERSHEY_SIMPLEX, 0.45, (80, 80, 80), 1, cv2.LINE_AA)
    path = out_dir / name
    if not cv2.imwrite(str(path), img):  # BGR: the colours above are BGR
        return None
    return path
