"""Downloading one catalog sequence: resumable, verified, unpacked atomically.

The archive streams into ``DIR/.fetch/<archive>.part``. When a ``.part`` is there from an earlier, interrupted
try, the request asks for the rest (``Range: bytes=N-``): a 206 appends, a 200 (the server ignores ranges)
starts over. A complete download is then verified - its size against the catalog's (when known) or the size
the server announced, its sha256 when the catalog has one, the whole gzip/zip read back with its own checksums,
and the TUM layout inside (rgb.txt, depth.txt, rgb/, depth/ under the expected folder) - and only then unpacked,
by storage's safe extraction (no absolute paths, ``..``, links or bombs), into a staging folder next to the
destination that is renamed into place in one step. A verification failure deletes the ``.part`` (it is not a
prefix worth resuming) and leaves nothing unpacked; an interrupted transfer keeps the ``.part`` to resume from.
"""
from __future__ import annotations

import contextlib
import gzip
import hashlib
import http.client
import json
import os
import re
import tarfile
import tempfile
import urllib.error
import urllib.parse
import urllib.request
import zipfile
import zlib
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from tqdm import tqdm

from cli.fetch.catalog import Dataset
from formats.errors import VtdError

CHUNK = 1 << 16
TIMEOUT_S = 60.0
USER_AGENT = "vtdslam-fetch"
LAYOUT = ("rgb.txt", "depth.txt", "rgb/", "depth/")
"""What a sequence folder must hold (files, and folders with at least one file)."""
RETRYABLE = (408, 429)
"""HTTP statuses (besides 5xx) worth another try."""
STAGING = ".fetch"
"""Where downloads in progress live, inside the destination folder."""

class FetchError(VtdError):
    """A download that failed, was refused, or could not be unpacked; the message says which and why."""

    code = "fetch_failed"


class Interrupted(FetchError):
    """The transfer stopped before the end; the ``.part`` is kept and the next try resumes it."""

    code = "fetch_interrupted"


@dataclass(frozen=True, slots=True)
class Fetched:
    name: str
    folder: Path
    status: str
    """``"downloaded"``, ``"resumed"`` (an earlier ``.part`` was continued) or ``"present"`` (skipped)."""
    bytes: int = 0


def is_sequence(folder: Path) -> bool:
    """The folder holds rgb.txt, depth.txt and non-empty rgb/ and depth/ folders."""
    return (folder / "rgb.txt").is_file() and (folder / "depth.txt").is_file() and all(
        (folder / sub).is_dir() and any((folder / sub).iterdir()) for sub in ("rgb", "depth"))


def fetch(ds: Dataset, to: Path, *, url_base: str | None = None, retries: int = 2,
          progress: bool = False, timeout: float = TIMEOUT_S) -> Fetched:
    """Download, verify and unpack ``ds`` into ``to/<ds.folder>``; a complete folder already there is skipped.

    ``retries``: further tries after an interrupted transfer, each resuming where the last stopped.
    ``progress``: show a progress bar (tqdm, on stderr) per transfer."""
    to = Path(to)
    dest = to / ds.folder
    if dest.exists():
        if is_sequence(dest):
            return Fetched(ds.name, dest, "present")
        raise FetchError(f"{dest} exists but is not a complete sequence (no rgb.txt, depth.txt, rgb/ or depth/); "
                         "remove it and fetch again", {"path": str(dest)})
    part = to / STAGING / (ds.filename + ".part")
    part.parent.mkdir(parents=True, exist_ok=True)
    resumed = part.exists() and part.stat().st_size > 0
    try:
        return _fetch(ds, to, part, resumed, url_base, retries, progress, timeout)
    finally:
        with contextlib.suppress(OSError):
            part.parent.rmdir()  # only when empty: no .part kept to resume, nothing else in flight there


def _fetch(ds: Dataset, to: Path, part: Path, resumed: bool, url_base: str | None, retries: int, progress: bool,
           timeout: float) -> Fetched:
    url = ds.url(url_base)
    if urllib.parse.urlsplit(url).scheme not in ("http", "https"):
        raise FetchError(f"{url}: only http and https addresses can be fetched", {"url": url})
    total: int | None = None
    for attempt in range(retries + 1):
        try:
            total = _download(url, part, progress, timeout)
            break
        except Interrupted:
            if attempt == retries:
                raise
            resumed = True
    try:
        verify(ds, part, total)
    except FetchError:
        part.unlink(missing_ok=True)
        raise
    size = part.stat().st_size
    try:
        _unpack(ds, part, to)
    except FetchError:  # an archive that cannot be unpacked safely is no better on the next try
        part.unlink(missing_ok=True)
        raise
    part.unlink()
    return Fetched(ds.name, to / ds.folder, "resumed" if resumed else "downloaded", size)


def _download(url: str, part: Path, progress: bool, timeout: float) -> int | None:
    """Fetch ``url`` into ``part``, continuing what is there. Returns the full size the server announced."""
    have = part.stat().st_size if part.exists() else 0
    req = urllib.request.Request(url, headers={"User-Agent": USER_AGENT})
    if have:
        req.add_header("Range", f"bytes={have}-")
    try:
        resp = urllib.request.urlopen(req, timeout=timeout)
    except urllib.error.HTTPError as exc:
        if exc.code == 416 and have:  # nothing after `have`: complete when the server's size says so
            total = _range_total(exc.headers.get("Content-Range"))
            if total == have:
                return total
            part.unlink()
            raise Interrupted(f"{url}: the server refused to resume at byte {have}; starting over", {"url": url}) \
                from None
        error = Interrupted if exc.code in RETRYABLE or exc.code >= 500 else FetchError
        raise error(f"{url}: HTTP {exc.code} {exc.reason}", {"url": url, "status": exc.code}) from None
    except (urllib.error.URLError, OSError) as exc:
        reason = getattr(exc, "reason", exc)
        raise Interrupted(f"{url}: {reason}", {"url": url}) from None
    with resp:
        length = resp.headers.get("Content-Length")
        body = int(length) if length is not None and length.isdigit() else None
        if resp.status == 206 and have:
            start = _range_start(resp.headers.get("Content-Range"))
            if start != have:  # not the rest we asked for: start over
                part.unlink()
                raise Interrupted(f"{url}: asked to resume at byte {have}, the server sent from {start}; "
                                  "starting over", {"url": url})
            total = _range_total(resp.headers.get("Content-Range"))
            mode = "ab"
        else:  # 200: the whole file (a server that ignores Range restarts the download)
            start, total, mode = 0, body, "wb"
        if total is None and body is not None:
            total = start + body
        done = start
        with open(part, mode) as fh, tqdm(total=total, initial=start, unit="B", unit_scale=True,
                                          unit_divisor=1024, desc=part.name.removesuffix(".part"),
                                          disable=not progress, dynamic_ncols=True, leave=False) as bar:
            try:
                while chunk := resp.read(CHUNK):
                    fh.write(chunk)
                    done += len(chunk)
                    bar.update(len(chunk))
            except (OSError, http.client.HTTPException) as exc:  # reset, timeout, IncompleteRead
                raise Interrupted(f"{url}: transfer stopped at byte {done} ({exc!r}); fetch again to resume",
                                  {"url": url, "bytes": done, "total": total}) from None
    if total is not None and done < total:
        raise Interrupted(f"{url}: transfer stopped at byte {done} of {total}; fetch again to resume",
                          {"url": url, "bytes": done, "total": total})
    return total


def _range_start(header: str | None) -> int | None:
    m = re.match(r"bytes (\d+)-\d+/(\d+|\*)", header or "")
    return int(m.group(1)) if m else None


def _range_total(header: str | None) -> int | None:
    m = re.match(r"bytes (?:\d+-\d+|\*)/(\d+)", header or "")
    return int(m.group(1)) if m else None


def verify(ds: Dataset, archive: Path, announced: int | None = None) -> None:
    """Refuse ``archive`` unless its size, sha256 (when known), compression checksums and layout are right."""
    size = archive.stat().st_size
    expected = ds.size if ds.size is not None else announced
    if expected is not None and size != expected:
        raise FetchError(f"{ds.name}: the download has {size} bytes, expected {expected}; it was deleted",
                         {"bytes": size, "expected": expected})
    if ds.sha256 is not None:
        digest = _sha256(archive)
        if digest != ds.sha256.lower():
            raise FetchError(f"{ds.name}: sha256 mismatch (got {digest}, expected {ds.sha256}); the download "
                             "was deleted", {"sha256": digest, "expected": ds.sha256})
    try:
        names = _tgz_names(archive) if ds.kind == "tgz" else _zip_names(archive)
    except (OSError, EOFError, tarfile.TarError, zipfile.BadZipFile, zlib.error) as exc:
        raise FetchError(f"{ds.name}: the {ds.kind} archive is damaged or incomplete ({exc}); it was deleted",
                         {"kind": ds.kind}) from None
    missing = [entry for entry in LAYOUT if not _has(names, ds.folder, entry)]
    if missing:
        raise FetchError(f"{ds.name}: the archive has no {', '.join(missing)} under {ds.folder}/ (not a TUM-layout "
                         "sequence); it was deleted", {"missing": missing})


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def _tgz_names(archive: Path) -> list[str]:
    """Every member name, reading the whole gzip stream to its end (its CRC and length are checked there)."""
    with gzip.open(archive, "rb") as gz:
        with tarfile.open(fileobj=gz, mode="r|") as tar:  # streaming: one pass, no seeking
            names = [m.name + ("/" if m.isdir() else "") for m in tar]
        while gz.read(1 << 20):  # past tar's end blocks to the gzip trailer
            pass
    return names


def _zip_names(archive: Path) -> list[str]:
    with zipfile.ZipFile(archive) as zf:
        bad = zf.testzip()
        if bad is not None:
            raise zipfile.BadZipFile(f"bad CRC in {bad}")
        return zf.namelist()


def _has(names: Iterable[str], folder: str, entry: str) -> bool:
    want = PurePosixPath(folder, entry.rstrip("/"))
    for name in names:
        path = PurePosixPath(name[2:] if name.startswith("./") else name)
        if entry.endswith("/"):
            if want in path.parents and not name.endswith("/"):
                return True
        elif path == want:
            return True
    return False


def _unpack(ds: Dataset, archive: Path, to: Path) -> None:
    """Extract into a staging folder next to the destination, add camera.json, rename into place."""
    from storage.ingest.archive import Limits, remove_tree, unpack

    limits = Limits(max_files=500_000, max_bytes=200 << 30, max_ratio=50.0)
    staging = Path(tempfile.mkdtemp(prefix=f".{ds.folder}.", suffix=".unpacking", dir=to))
    try:
        try:
            unpack(archive, staging, limits)
        except VtdError as exc:
            raise FetchError(f"{ds.name}: cannot unpack: {exc}", {"path": str(archive)}) from None
        root = staging / ds.folder
        if not is_sequence(root):
            raise FetchError(f"{ds.name}: the unpacked {ds.folder}/ is not a complete sequence")
        _write_camera(root, ds.camera)
        os.rename(root, to / ds.folder)
    finally:
        remove_tree(staging)


def _write_camera(folder: Path, preset: str) -> None:
    """The preset's intrinsics as the sequence's camera.json (`run` and the upload read it), unless it has one."""
    from formats.camera_spec import check_intrinsics
    from formats.catalog import CAMERA_PRESETS

    path = folder / "camera.json"
    if path.exists():
        return
    spec: dict[str, Any] = {**asdict(CAMERA_PRESETS[preset]), "name": preset}
    spec["dist"] = list(spec["dist"])
    path.write_text(json.dumps(check_intrinsics(spec), indent=1) + "\n")

