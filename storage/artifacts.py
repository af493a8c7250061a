"""The artifact store: files of sequences and job runs under the data directory.

Layout under ``root`` (the data dir)::

    sequences/<sequence_id>/   an unpacked TUM-layout sequence
    artifacts/<job_id>/<name>  a run's outputs (trajectory.txt, map.ply, metrics.json, …)
    staging/                   uploads being unpacked; same filesystem, so installing is a rename

Writes are atomic (temp file + ``os.replace``): a reader never sees a half-written artifact.
"""

from __future__ import annotations

import builtins
import functools
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Literal

from storage.errors import Conflict, InvalidInput, NotFound, Unreadable
from storage.faults import disk_full, insufficient_storage
from storage.settings import Settings

_ID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
_TMP_PREFIX = ".tmp-"


@dataclass(frozen=True, slots=True)
class ArtifactInfo:
    name: str
    size_bytes: int


@functools.cache
def file_mode() -> int:
    """The mode of files the service creates: 0666 minus the process umask, as for any ``open()``
    (0644 under the usual 022; 027 gives 0640, readable by the group only), artifacts and sequences alike."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            umask = next(int(line.split()[1], 8) for line in fh if line.startswith("Umask:"))
    except (OSError, StopIteration, ValueError, IndexError):
        umask = os.umask(0o022)  # no /proc: read it by setting it (then put it back)
        os.umask(umask)
    return 0o666 & ~umask


def check_name(name: str) -> str:
    """A plain file name: no separators, no ``..``, not hidden (temp files are)."""
    if (
        not name
        or name in {".", ".."}
        or name.startswith(".")
        or any(c in name for c in "/\\\0")
        or len(name) > 255
    ):
        raise InvalidInput(f"invalid artifact name {name!r}", {"name": name})
    return name


def _check_id(key: str, what: str) -> str:
    if not _ID.match(key):
        raise InvalidInput(f"invalid {what} id {key!r}", {"id": key})
    return key


class ArtifactStore:
    """Files of sequences and jobs below ``root`` (normally ``settings.data_dir``)."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    # -- directories ------------------------------------------------------------------------------

    def job_dir(self, job_id: str, *, create: bool = False) -> Path:
        path = self.root / "artifacts" / _check_id(job_id, "job")
        if create:
            path.mkdir(parents=True, exist_ok=True)
        return path

    def sequence_dir(self, seq_id: str) -> Path:
        return self.root / "sequences" / _check_id(seq_id, "sequence")

    def staging_dir(self) -> Path:
        """Where uploads are unpacked before :meth:`install_sequence` renames them into place."""
        path = self.root / "staging"
        path.mkdir(parents=True, exist_ok=True)
        return path

    def new_staging_dir(self, prefix: str = "upload-") -> Path:
        """A fresh, empty, uniquely named directory in :meth:`staging_dir`."""
        try:
            return Path(tempfile.mkdtemp(prefix=prefix, dir=self.staging_dir()))
        except OSError as exc:
            if disk_full(exc):
                raise insufficient_storage("starting the upload") from exc
            raise

    def install_sequence(self, src: Path, seq_id: str) -> Path:
        """Move a staged sequence folder to :meth:`sequence_dir` (a rename on the same filesystem)."""
        dest = self.sequence_dir(seq_id)
        if dest.exists():
            raise Conflict(f"sequence {seq_id} already has files", {"id": seq_id})
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(src), str(dest))  # os.rename when possible; copies across filesystems
        return dest

    def relative(self, path: Path) -> str:
        """``path`` relative to the root if inside it (what ``Sequence.path`` stores), else absolute."""
        path = Path(path).resolve()
        try:
            return path.relative_to(self.root.resolve()).as_posix()
        except ValueError:
            return str(path)

    def resolve(self, stored: str) -> Path:
        """The absolute path of a stored ``Sequence.path`` (relative paths are below the root)."""
        path = Path(stored)
        return path if path.is_absolute() else self.root / path

    # -- job artifacts ----------------------------------------------------------------------------

    @contextmanager
    def open_write(
        self, job_id: str, name: str, mode: Literal["wb", "w"] = "wb"
    ) -> Iterator[IO[Any]]:
        """A file to write artifact ``name``; it appears under its name only if the block succeeds."""
        if mode not in ("wb", "w"):
            raise InvalidInput(f"mode must be 'wb' or 'w', not {mode!r}")
        folder = self.job_dir(job_id, create=True)
        target = folder / check_name(name)
        fd, tmp = tempfile.mkstemp(prefix=_TMP_PREFIX, dir=folder)
        try:
            os.fchmod(fd, file_mode())  # mkstemp's 0600 would hide the file from an api of another user
            with os.fdopen(fd, str(mode), encoding="utf-8" if mode == "w" else None) as fh:
                yield fh
                fh.flush()
                os.fsync(fh.fileno())  # the data is on disk before the name points at it
            os.replace(tmp, target)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    def write_bytes(self, job_id: str, name: str, data: bytes) -> Path:
        with self.open_write(job_id, name) as fh:
            fh.write(data)
        return self.job_dir(job_id) / name

    def write_text(self, job_id: str, name: str, text: str) -> Path:
        with self.open_write(job_id, name, "w") as fh:
            fh.write(text)
        return self.job_dir(job_id) / name

    def put_file(self, job_id: str, name: str, src: Path) -> Path:
        """Copy an existing file in as artifact ``name`` (atomically, like every write)."""
        with self.open_write(job_id, name) as fh, open(src, "rb") as inp:
            shutil.copyfileobj(inp, fh, 1 << 20)
        return self.job_dir(job_id) / name

    def path(self, job_id: str, name: str) -> Path:
        """The path of an existing artifact, for reading or serving; :class:`NotFound` otherwise."""
        path = self.job_dir(job_id) / check_name(name)
        try:
            is_file = stat.S_ISREG(os.stat(path).st_mode)
        except (FileNotFoundError, NotADirectoryError):
            is_file = False
        except OSError as exc:  # the job's folder is not ours to read: say so, not "no such artifact"
            raise _unreadable(f"job {job_id}'s artifact {name!r}", exc) from exc
        if not is_file:
            raise NotFound(f"job {job_id} has no artifact {name!r}", {"job_id": job_id, "name": name})
        return path

    def list(self, job_id: str) -> builtins.list[ArtifactInfo]:
        """A job's finished artifacts by name (empty if it has none yet)."""
        folder = self.job_dir(job_id)
        found = []
        try:
            with os.scandir(folder) as entries:
                for entry in entries:
                    if entry.name.startswith("."):
                        continue
                    try:
                        st = entry.stat()
                    except FileNotFoundError:  # replaced or deleted while listing
                        continue
                    if stat.S_ISREG(st.st_mode):
                        found.append(ArtifactInfo(entry.name, st.st_size))
        except (FileNotFoundError, NotADirectoryError):
            return []
        except OSError as exc:  # a folder the api may not read: a clear error, not a 500
            raise _unreadable(f"job {job_id}'s artifacts", exc) from exc
        return sorted(found, key=lambda a: a.name)

    # -- deletion ---------------------------------------------------------------------------------

    def delete_job(self, job_id: str) -> None:
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)

    def delete_staging(self, prefix: str) -> None:
        """Remove staging folders named ``prefix*`` (a dead worker's scratch space for one job)."""
        folder = self.root / "staging"
        if not folder.is_dir() or not _ID.match(prefix.rstrip("-")):
            return
        for path in folder.glob(f"{prefix}*"):
            shutil.rmtree(path, ignore_errors=True)

    def delete_sequence(self, seq_id: str) -> None:
        shutil.rmtree(self.sequence_dir(seq_id), ignore_errors=True)


def _unreadable(what: str, exc: OSError) -> Unreadable:
    return Unreadable(f"the server cannot read {what} ({exc.strerror or exc}); check the data dir's permissions",
                      {"errno": exc.errno})


def make_artifact_store(settings: Settings) -> ArtifactStore:
    return ArtifactStore(settings.data_dir)
