"""The named benchmark sequences `vtdslam fetch` knows, as data: where each lives on its official site, what
kind of archive it is, what it unpacks to and which camera preset describes it; and the named bench tables.

Sizes and sha256 digests are recorded only where they are known for certain. Neither site publishes digests,
and this catalog was written without network access, so every entry leaves both unknown (``None``): a
download is then checked against the size the server announces (Content-Length / Content-Range) and
structurally (the whole gzip or zip reads back with its checksums, and the TUM layout is inside: rgb.txt,
depth.txt, rgb/, depth/ under the expected folder). Fill ``size``/``sha256`` in when they are measured and
the check becomes exact.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

TUM_BASE = "https://cvg.cit.tum.de/rgbd/dataset/"
BONN_BASE = "https://www.ipb.uni-bonn.de/html/projects/rgbd_dynamic2019/"


@dataclass(frozen=True, slots=True)
class Dataset:
    """One downloadable sequence."""

    name: str
    """The short name `vtdslam fetch` takes, e.g. ``tum-fr3-walking-xyz``."""
    base: str
    """The official site's folder; ``--url-base`` replaces it (tests point it at 127.0.0.1)."""
    path: str
    """The archive's path below ``base``."""
    kind: str
    """``"tgz"`` (TUM) or ``"zip"`` (Bonn)."""
    folder: str
    """The top-level folder inside the archive, and the sequence folder it unpacks to."""
    camera: str
    """The camera preset (formats.catalog.CAMERA_PRESETS) written to the sequence's camera.json."""
    size: int | None = None
    """The archive's size in bytes, when known."""
    sha256: str | None = None
    """The archive's sha256 (hex), when known."""

    @property
    def filename(self) -> str:
        return self.path.rsplit("/", 1)[-1]

    def url(self, base: str | None = None) -> str:
        """The archive's address on the official site, or below ``base`` instead."""
        return (self.base if base is None else base.rstrip("/") + "/") + self.path


def _tum(name: str, freiburg: int, scene: str) -> Dataset:
    folder = f"rgbd_dataset_freiburg{freiburg}_{scene}"
    return Dataset(name, TUM_BASE, f"freiburg{freiburg}/{folder}.tgz", "tgz", folder, f"tum{freiburg}")


def _bonn(name: str, scene: str) -> Dataset:
    folder = f"rgbd_bonn_{scene}"
    return Dataset(name, BONN_BASE, f"{folder}.zip", "zip", folder, "bonn")


DATASETS: dict[str, Dataset] = {d.name: d for d in (
    # TUM RGB-D, dynamic objects (the paper's four walking sequences, and the sitting ones)
    _tum("tum-fr3-walking-xyz", 3, "walking_xyz"),
    _tum("tum-fr3-walking-static", 3, "walking_static"),
    _tum("tum-fr3-walking-rpy", 3, "walking_rpy"),
    _tum("tum-fr3-walking-halfsphere", 3, "walking_halfsphere"),
    _tum("tum-fr3-sitting-xyz", 3, "sitting_xyz"),
    _tum("tum-fr3-sitting-static", 3, "sitting_static"),
    # TUM RGB-D, static scenes
    _tum("tum-fr1-xyz", 1, "xyz"),
    _tum("tum-fr1-desk", 1, "desk"),
    _tum("tum-fr2-desk", 2, "desk"),
    _tum("tum-fr2-xyz", 2, "xyz"),
    # Bonn RGB-D Dynamic (its groundtruth.txt is the marker's pose, as published)
    _bonn("bonn-crowd", "crowd"),
    _bonn("bonn-crowd2", "crowd2"),
    _bonn("bonn-crowd3", "crowd3"),
    _bonn("bonn-person-tracking", "person_tracking"),
    _bonn("bonn-person-tracking2", "person_tracking2"),
    _bonn("bonn-moving-nonobstructing-box", "moving_nonobstructing_box"),
    _bonn("bonn-moving-obstructing-box", "moving_obstructing_box"),
    _bonn("bonn-balloon", "balloon"),
    _bonn("bonn-synchronous", "synchronous"),
)}

TABLES: dict[str, tuple[str, ...]] = {
    "tum-walking": ("tum-fr3-walking-xyz", "tum-fr3-walking-static", "tum-fr3-walking-rpy",
                    "tum-fr3-walking-halfsphere"),
    "bonn-crowd": ("bonn-crowd", "bonn-crowd2", "bonn-crowd3"),
}
"""Named bench tables (``bench/bench_named.py --table``): the paper's four TUM walking sequences, Bonn crowd."""


def lookup(name: str) -> Dataset:
    """A dataset by its short name or its official folder name; KeyError with the choices otherwise."""
    if name in DATASETS:
        return DATASETS[name]
    for d in DATASETS.values():
        if name in (d.folder, d.filename):
            return d
    raise KeyError(name)


def table_sequences(table: str, data: Path) -> tuple[list[tuple[Dataset, Path]], list[Dataset]]:
    """A bench table's sequences fetched into ``data`` (each with its folder), and those not there."""
    if table not in TABLES:
        raise KeyError(table)
    present, missing = [], []
    for ds in (DATASETS[n] for n in TABLES[table]):
        folder = Path(data) / ds.folder
        if (folder / "rgb.txt").is_file() and (folder / "depth.txt").is_file():
            present.append((ds, folder))
        else:
            missing.append(ds)
    return present, missing
