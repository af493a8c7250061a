"""TUM trajectory files: ``t tx ty tz qx qy qz qw`` per line (camera-to-world T_WC, scalar-last quaternion)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from formats.errors import FormatError

QUATERNION_NORM_TOLERANCE = 0.1
"""A quaternion whose norm is further than this from 1 is rejected (rounded files are normalised on use)."""


@dataclass(frozen=True)
class TumTrajectory:
    """``timestamps`` (N,) float64 seconds, ``positions`` (N, 3) float64 camera centres in the world,
    ``quaternions`` (N, 4) float64 ``qx qy qz qw`` of T_WC's rotation, as written in the file."""

    timestamps: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.timestamps)
        if self.positions.shape != (n, 3) or self.quaternions.shape != (n, 4):
            raise ValueError(f"need (N,3) positions and (N,4) quaternions for {n} timestamps, "
                             f"got {self.positions.shape}, {self.quaternions.shape}")

    def __len__(self) -> int:
        return len(self.timestamps)


def parse_tum_trajectory(text: str, path: Path | str | None = None) -> TumTrajectory:
    """The poses of a trajectory file's text, sorted by time (stable); may be empty. Blank lines and ``#``
    comments are skipped, commas count as spaces. ``path`` only names the file in errors."""
    rows: list[list[float]] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        if len(parts) != 8:
            raise FormatError(f"expected 8 values (t tx ty tz qx qy qz qw), got {len(parts)}", path=path, line=lineno)
        try:
            values = [float(v) for v in parts]
        except ValueError:
            raise FormatError(f"not a number in {s[:80]!r}", path=path, line=lineno) from None
        if not all(math.isfinite(v) for v in values):
            raise FormatError("non-finite value", path=path, line=lineno)
        if abs(math.sqrt(sum(q * q for q in values[4:8])) - 1.0) > QUATERNION_NORM_TOLERANCE:
            raise FormatError("quaternion is not unit length", path=path, line=lineno)
        rows.append(values)
    table = np.asarray(rows, dtype=np.float64).reshape(-1, 8)
    table = table[np.argsort(table[:, 0], kind="stable")]
    return TumTrajectory(table[:, 0].copy(), table[:, 1:4].copy(), table[:, 4:8].copy())


def read_tum_trajectory(path: Path | str) -> TumTrajectory:
    """:func:`parse_tum_trajectory` of a file that must exist and hold at least one pose."""
    path = Path(path)
    if not path.is_file():
        raise FormatError("file not found", path=path)
    traj = parse_tum_trajectory(path.read_text(encoding="utf-8", errors="replace"), path)
    if not len(traj):
        raise FormatError("no poses", path=path)
    return traj


def write_tum_trajectory(path: Path | str, traj: TumTrajectory, header: str | None = None) -> None:
    """Write atomically (temp file + rename) so a reader never sees half a trajectory; 6 decimals for time,
    7 for the rest."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    with tmp.open("w") as fh:
        fh.write(f"# {header or 'trajectory T_WC'}\n# timestamp tx ty tz qx qy qz qw\n")
        for t, p, q in zip(traj.timestamps, traj.positions, traj.quaternions):
            fh.write(f"{t:.6f} " + " ".join(f"{v:.7f}" for v in (*p, *q)) + "\n")
    tmp.replace(path)
