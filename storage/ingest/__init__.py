"""Accepting sequences: an uploaded archive (unpacked in staging, validated, installed atomically) or a
folder already on the server below ``settings.import_root`` (validated, registered in place).

Either everything lands (files in place and a database row) or nothing does.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from sqlalchemy.orm import Session

from storage.artifacts import ArtifactStore
from storage.errors import InvalidInput, NotFound, StorageError
from storage.faults import disk_full, insufficient_storage
from storage.ingest.archive import Limits, find_root, remove_tree, unpack
from storage.ingest.bag import BagLimits, find_bag_folder, import_bag, import_uploaded_bag, sniff_bag
from storage.ingest.sequence import SequenceInfo, validate_sequence
from storage.models import Sequence, new_id
from storage.repositories import sequences
from storage.settings import Settings

__all__ = [
    "SequenceInfo",
    "ingest_staged",
    "register_folder",
    "sweep_stale_uploads",
    "upload_limits",
    "validate_sequence",
]


def upload_limits(settings: Settings) -> Limits:
    """Unpacked totals may reach 4x the largest upload (and ``max_ratio`` x the archive's own size)."""
    return Limits(
        max_files=settings.max_files,
        max_bytes=4 * settings.max_upload_bytes,
        max_ratio=settings.max_ratio,
    )


def ingest_staged(
    session: Session,
    store: ArtifactStore,
    settings: Settings,
    staging: Path,
    *,
    name: str,
    camera: dict[str, Any],
    content_sha256: str | None = None,
    unique: bool = False,
) -> Sequence:
    """Validate, install and record an upload in the staging folder ``staging``.

    ``unique``: refuse (:class:`Conflict`) when another sequence already holds ``content_sha256``.

    ``staging`` holds ``archive`` (unpacked here into ``unpacked``) or, when the upload was unpacked
    while it streamed in (:class:`storage.ingest.stream.ArchiveSink`), ``unpacked`` already. A ROS bag
    (a ROS 1 ``.bag``, a ROS 2 ``.mcap`` or ``.db3`` file, told by their magic bytes, or an archive of a ROS 2
    bag folder with its ``metadata.yaml``) is converted into ``unpacked`` by :mod:`storage.ingest.bag` under
    the same limits (topics found automatically; camera.json from its CameraInfo wins over ``camera``).
    ``staging`` is removed in every case; a failure leaves neither files nor a row behind.
    """
    seq_id = new_id()
    installed: Path | None = None
    try:
        unpacked = staging / "unpacked"
        archive = staging / "archive"
        limits = upload_limits(settings)
        bag_limits = BagLimits(max_files=limits.max_files, max_bytes=limits.max_bytes)
        bag_kind = sniff_bag(archive) if archive.exists() else None
        if bag_kind is not None:
            import_uploaded_bag(archive, bag_kind, unpacked, bag_limits)
            for leftover in staging.glob("archive*"):
                leftover.unlink()  # free the space before validating
        elif archive.exists():
            unpacked.mkdir()
            unpack(archive, unpacked, limits)
            archive.unlink()  # free the space before validating
        if not (unpacked / "rgb.txt").is_file() and (bag_folder := find_bag_folder(unpacked)) is not None:
            converted = staging / "converted"
            import_bag(bag_folder, converted, limits=bag_limits)
            remove_tree(bag_folder)
            unpacked = converted
        root = find_root(unpacked)
        info = validate_sequence(root, camera)
        installed = store.install_sequence(root, seq_id)
        return _record(
            session, store, seq_id, installed, info,
            name=name, camera=camera, source="upload", content_sha256=content_sha256, claim=unique,
        )
    except BaseException as exc:
        if installed is not None:
            store.delete_sequence(seq_id)
        if not isinstance(exc, StorageError) and disk_full(exc):  # unpacking or installing filled the disk
            raise insufficient_storage("unpacking the upload") from exc
        raise
    finally:
        remove_tree(staging)


def register_folder(
    session: Session,
    store: ArtifactStore,
    settings: Settings,
    folder: str,
    *,
    name: str | None,
    camera: dict[str, Any],
) -> Sequence:
    """Register a server folder in place; it must resolve below ``settings.import_root``."""
    if settings.import_root is None:
        raise InvalidInput("registering server folders is disabled (VTD_IMPORT_ROOT is not set)")
    root = settings.import_root.resolve()
    if "\x00" in folder:  # the OS would refuse it with a ValueError (a 500), not an OSError
        raise InvalidInput("the folder path contains a NUL byte", {"path": folder})
    path = Path(folder)
    try:
        # resolve() follows symlinks, so a link inside the root that points outside is refused too
        target = (path if path.is_absolute() else root / path).resolve()
        if not target.is_relative_to(root):
            raise InvalidInput("the folder must be inside the import root", {"path": folder})
        is_dir = target.is_dir()
    except (OSError, RuntimeError) as exc:  # a name too long, a symlink loop (RuntimeError before 3.13), …
        reason = getattr(exc, "strerror", None) or "symlink loop"
        raise InvalidInput(f"unusable folder path: {reason}", {"path": folder}) from None
    if not is_dir:
        raise NotFound(f"no folder {folder!r} under the import root", {"path": folder})
    info = validate_sequence(target, camera)
    return _record(
        session, store, new_id(), target, info, name=name or target.name, camera=camera, source="import"
    )


def sweep_stale_uploads(store: ArtifactStore, older_than_s: float = 6 * 3600) -> list[str]:
    """Remove upload staging folders nobody touched for ``older_than_s`` (an api killed mid-upload).

    Age, not ownership, decides: several api processes may share the data dir and be mid-upload.
    """
    removed = []
    now = time.time()
    for path in store.staging_dir().glob("upload-*"):
        try:
            newest = max([path.stat().st_mtime] + [p.stat().st_mtime for p in path.iterdir()])
        except OSError:
            continue
        if now - newest > older_than_s:
            remove_tree(path)
            removed.append(path.name)
    return removed


def _record(
    session: Session,
    store: ArtifactStore,
    seq_id: str,
    path: Path,
    info: SequenceInfo,
    *,
    name: str,
    camera: dict[str, Any],
    source: str,
    content_sha256: str | None = None,
    claim: bool = False,
) -> Sequence:
    try:
        return sequences.create(
            session,
            id=seq_id,
            name=name,
            path=store.relative(path),
            frames=info.frames,
            duration_s=info.duration_s,
            has_groundtruth=info.has_groundtruth,
            camera=camera,
            size_bytes=info.size_bytes,
            meta={**info.meta(), "source": source},
            content_sha256=content_sha256,
            claim=claim,
        )
    except StorageError:
        raise
    except Exception as exc:  # the database refused: surface it, the caller cleans the files
        if disk_full(exc):
            raise insufficient_storage("recording the sequence") from exc
        raise StorageError(f"could not record the sequence: {exc}") from exc
