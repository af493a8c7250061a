"""A worker's name, unique among the live workers that share one data directory.

The name is stored on the jobs a worker claims, and a worker starting under a name reaps the jobs still
running under it as orphans. Two live workers with one name would therefore reap each other's jobs, so
each holds an exclusive lock on ``data_dir/workers/<name>.lock`` while it runs; the kernel drops the
lock when the process dies (even on ``kill -9``), which is what tells a restart that the name is free.
Locks are ``flock``: local disks and Docker volumes, and NFSv4 (Linux maps them to NFS byte-range locks).
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import re
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from storage.errors import ConfigurationError

MAX_PER_HOST = 64


@dataclass
class WorkerName:
    """A name held by this process until :meth:`release` (or its exit)."""

    name: str
    lock: IO[str]
    path: Path

    def touch(self) -> None:
        """Mark this worker alive and connected (its mtime is what ``worker.health`` checks)."""
        os.utime(self.path)

    def release(self) -> None:
        self.lock.close()


def lock_path(data_dir: Path, name: str) -> Path:
    return _lock_path(Path(data_dir) / "workers", name)


def host_names(requested: str | None = None) -> list[str]:
    """The names a worker on this host tries, in order."""
    host = socket.gethostname()
    return [requested] if requested else [host, *(f"{host}-{i}" for i in range(2, MAX_PER_HOST + 1))]


def is_held(path: Path) -> bool:
    """Whether a live process holds the lock at ``path``."""
    if not path.is_file():
        return False
    lock = _try_lock(path, note=False)
    if lock is None:
        return True
    lock.close()
    return False


def _lock_path(folder: Path, name: str) -> Path:
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", name)[:64]
    return folder / f"{safe}-{hashlib.sha1(name.encode()).hexdigest()[:8]}.lock"


def _try_lock(path: Path, note: bool = True) -> IO[str] | None:
    fh = open(path, "a+", encoding="utf-8")
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        fh.close()
        return None
    if not note:
        return fh
    fh.seek(0)
    fh.truncate()
    fh.write(f"{os.getpid()}\n")  # for a human looking at the folder
    fh.flush()
    return fh


def claim_name(data_dir: Path, requested: str | None = None) -> WorkerName:
    """Hold ``requested``, or the host name (then ``host-2``, ``host-3``, … if taken by live workers).

    A restarted worker gets its old name back when its predecessor is dead, so it reaps that one's
    orphans. :class:`ConfigurationError` when an explicitly requested name is held by a live worker.
    """
    folder = Path(data_dir) / "workers"
    folder.mkdir(parents=True, exist_ok=True)
    for name in host_names(requested):
        path = _lock_path(folder, name)
        lock = _try_lock(path)
        if lock is not None:
            return WorkerName(name, lock, path)
    if requested:
        raise ConfigurationError(
            f"a worker named {requested!r} is already running on this data directory; give each worker "
            "its own --name (a second one would fail the first one's running jobs as orphans)",
            {"name": requested},
        )
    raise ConfigurationError(f"more than {MAX_PER_HOST} workers named after this host are running")
