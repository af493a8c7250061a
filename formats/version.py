"""Which code produced a result: the package version and, run from a git checkout, the commit.

metrics.json and config.json carry both (keys :data:`VERSION_KEY`, :data:`COMMIT_KEY`), the job page shows
them and ``vtdslam --version`` prints them. The commit is read from the checkout's ``.git`` files (``HEAD``, the
ref it names, ``packed-refs``; a worktree's ``.git`` file and its common dir too): no git library, no ``git``
program. Anything missing or unreadable gives None; nothing here raises.
"""

from __future__ import annotations

import re
from functools import cache
from importlib import metadata
from pathlib import Path

DISTRIBUTION = "vtdslam"
UNKNOWN_VERSION = "0+unknown"
VERSION_KEY = "version"
COMMIT_KEY = "commit"
PROVENANCE_KEYS = (VERSION_KEY, COMMIT_KEY)
"""Keys a run's metrics.json and config.json carry besides their own content."""

CHECKOUT = Path(__file__).resolve().parent.parent
"""The folder holding the ``formats`` package: a git checkout's root when the code runs from one."""

_SHA = re.compile(r"^[0-9a-f]{40}([0-9a-f]{24})?$")


def package_version() -> str:
    """The installed ``vtdslam`` distribution's version (pyproject.toml), or ``0+unknown`` when not installed."""
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return UNKNOWN_VERSION


def _read(path: Path) -> str | None:
    try:
        return path.read_text(encoding="utf-8", errors="replace").strip()
    except OSError:
        return None


def _git_dirs(root: Path) -> tuple[Path, Path] | None:
    """(the git dir holding HEAD, the common dir holding refs) of the checkout at ``root``, or None."""
    dot = root / ".git"
    if dot.is_dir():
        return dot, dot
    text = _read(dot) if dot.is_file() else None  # a worktree or submodule: "gitdir: PATH"
    if not text or not text.startswith("gitdir:"):
        return None
    gitdir = Path(text.partition(":")[2].strip())
    gitdir = gitdir if gitdir.is_absolute() else (root / gitdir)
    common = _read(gitdir / "commondir")
    common_dir = (gitdir / common) if common else gitdir
    return gitdir, common_dir


def _resolve_ref(ref: str, dirs: tuple[Path, Path]) -> str | None:
    for base in dict.fromkeys(dirs):  # a worktree's own refs first, then the shared ones
        sha = _read(base / ref)
        if sha and _SHA.match(sha):
            return sha
    packed = _read(dirs[1] / "packed-refs") or ""
    for line in packed.splitlines():
        sha, _, name = line.partition(" ")
        if name.strip() == ref and _SHA.match(sha):
            return sha
    return None


def git_commit(root: Path | None = None) -> str | None:
    """The commit checked out at ``root`` (default :data:`CHECKOUT`), 40 hex digits; None outside a checkout or
    where the files cannot be read (an installed wheel, a copy without ``.git``, an unborn branch)."""
    try:
        dirs = _git_dirs(root or CHECKOUT)
        if dirs is None:
            return None
        head = _read(dirs[0] / "HEAD")
        if not head:
            return None
        if _SHA.match(head):  # a detached HEAD
            return head
        if head.startswith("ref:"):
            return _resolve_ref(head.partition(":")[2].strip(), dirs)
    except (OSError, ValueError):
        pass
    return None


@cache
def provenance() -> dict[str, str | None]:
    """``{"version": ..., "commit": ...}`` of the running code (read once per process)."""
    return {VERSION_KEY: package_version(), COMMIT_KEY: git_commit()}


def describe(info: dict[str, str | None] | None = None) -> str:
    """``0.1.0 (commit 8bdf8d6a1b2c)`` or ``0.1.0`` without a commit: what ``vtdslam --version`` prints."""
    info = provenance() if info is None else info
    version, commit = info.get(VERSION_KEY) or UNKNOWN_VERSION, info.get(COMMIT_KEY)
    return f"{version} (commit {commit[:12]})" if commit else version
