"""A preview image of a finished run: the estimated trajectory seen from above (x-z plane, TUM camera
convention: y down), keyframes marked. Shown by the dashboard before the 3D viewer loads."""
from __future__ import annotations

from pathlib import Path

import numpy as np

SIZE = 480
MARGIN = 30


def _read_xyz(path: Path) -> np.ndarray:
    """(N, 3) positions of a TUM trajectory file (``t tx ty tz qx qy qz qw``); empty if none."""
    rows = [line.split() for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]
    return np.array([[float(r[1]), float(r[2]), float(r[3])] for r in rows if len(r) >= 8]).reshape(-1, 3)


def write_trajectory_preview(out_dir: Path, name: str = "preview.png") -> Path | None:
    """Draw ``trajectory.txt`` (and ``keyframes.txt``) of ``out_dir`` into ``out_dir/name``; None if empty."""
    import cv2

    traj = _read_xyz(out_dir / "trajectory.txt") if (out_dir / "trajectory.txt").is_file() else np.zeros((0, 3))
    if len(traj) < 2:
        return None
    kfs = _read_xyz(out_dir / "keyframes.txt") if (out_dir / "keyframes.txt").is_file() else np.zeros((0, 3))
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
