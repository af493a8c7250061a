"""Tiny TUM-layout sequences and archives made in code (shared by the api, worker and e2e tests).

The scene is a textured plane 1 m in front of a camera that translates parallel to it, so the real
pipeline tracks it; the ground truth matches the motion and is not degenerate (x and y both move).
"""
from __future__ import annotations

import io
import json
import tarfile
import zipfile
from pathlib import Path

import cv2
import numpy as np

SIZE = (160, 120)
CAMERA = {"fx": 100.0, "fy": 100.0, "cx": 80.0, "cy": 60.0, "depth_scale": 5000.0, "width": 160, "height": 120}


def write_sequence(root: Path, n: int = 20, size: tuple[int, int] = SIZE, *, gt: bool = True,
                   camera_json: bool = True) -> Path:
    """`n` frames of `size` (w, h) RGB-D; the camera moves 2 px/frame in x and along a sine in y."""
    (root / "rgb").mkdir(parents=True, exist_ok=True)
    (root / "depth").mkdir(exist_ok=True)
    w, h = size
    rng = np.random.default_rng(1)
    tex = cv2.GaussianBlur(rng.integers(0, 255, (h + 40, w + 2 * n + 40, 3), dtype=np.uint8), (3, 3), 0)
    depth = np.full((h, w), 5000, np.uint16)
    rgb_lines, depth_lines, gt_lines = ["# rgb"], ["# depth"], ["# timestamp tx ty tz qx qy qz qw"]
    for i in range(n):
        t = 100.0 + i / 30
        dy = int(round(8 * np.sin(i / 4)))
        cv2.imwrite(str(root / f"rgb/{t:.6f}.png"), tex[20 + dy:20 + dy + h, 20 + 2 * i:20 + 2 * i + w])
        cv2.imwrite(str(root / f"depth/{t:.6f}.png"), depth)
        rgb_lines.append(f"{t:.6f} rgb/{t:.6f}.png")
        depth_lines.append(f"{t:.6f} depth/{t:.6f}.png")
        gt_lines.append(f"{t:.6f} {i * 2 / CAMERA['fx']:.6f} {dy / CAMERA['fy']:.6f} 0 0 0 0 1")
    (root / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (root / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    if gt:
        (root / "groundtruth.txt").write_text("\n".join(gt_lines) + "\n")
    if camera_json:
        (root / "camera.json").write_text(json.dumps({**CAMERA, "width": w, "height": h,
                                                      "fx": CAMERA["fx"] * w / 160, "fy": CAMERA["fy"] * w / 160,
                                                      "cx": w / 2, "cy": h / 2}))
    return root


def tar_gz(folder: Path, out: Path, *, top: str | None = "seq") -> Path:
    """`folder` as a .tar.gz, inside one top-level folder `top` (None: its contents at the top)."""
    with tarfile.open(out, "w:gz") as tf:
        for p in sorted(folder.rglob("*")):
            rel = p.relative_to(folder).as_posix()
            tf.add(p, arcname=f"{top}/{rel}" if top else rel, recursive=False)
    return out


def zip_of(folder: Path, out: Path, *, top: str | None = "seq", stored: bool = False) -> Path:
    mode = zipfile.ZIP_STORED if stored else zipfile.ZIP_DEFLATED
    with zipfile.ZipFile(out, "w", mode) as zf:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                rel = p.relative_to(folder).as_posix()
                zf.write(p, f"{top}/{rel}" if top else rel)
    return out


def tar_with(entries: list[tarfile.TarInfo], payloads: dict[str, bytes] | None = None) -> bytes:
    """A .tar.gz of hand-made entries (links, devices, raw non-UTF-8 names) for the rejection tests."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz", format=tarfile.GNU_FORMAT, errors="surrogateescape") as tf:
        for info in entries:
            data = (payloads or {}).get(info.name)
            if data is not None:
                info.size = len(data)
                tf.addfile(info, io.BytesIO(data))
            else:
                tf.addfile(info)
    return buf.getvalue()
