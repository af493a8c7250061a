"""Unpacking an uploaded archive safely: .zip, .tar.gz/.tgz (and plain .tar), sniffed by content.

Every entry is checked before a byte is written: relative UTF-8 paths only (no absolute paths, drive
letters, ``..`` or backslashes), regular files and folders only (links, devices and FIFOs rejected), no
encrypted zip entries, at most ``max_files`` entries. Bytes are counted while they are written, so a
header that lies about sizes cannot get past ``max_bytes`` or the compression-ratio limit (bombs).
Metadata counts too: a tar's PAX and GNU long-name headers are checked (size, chain length) before
tarfile reads them into memory, and a zip's central directory (names, extra fields, comments) is
sized from its end record before zipfile reads it.
"""

from __future__ import annotations

import errno
import gzip
import os
import shutil
import stat
import struct
import tarfile
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import IO

from storage.errors import InvalidInput, PayloadTooLarge

CHUNK = 1 << 20
MAX_NAME_LEN = 1024
RATIO_FLOOR = 1 << 20
SKIPPED_TOP = {"__MACOSX"}  # resource forks macOS's archiver adds; never part of a sequence
MAX_META_BYTES = 64 * 1024
"""Largest PAX / GNU long-name header: names are at most MAX_NAME_LEN; tarfile reads the whole header
into memory (a 408 KB .tar.gz with a 1.5 GB PAX header took the api to 1.67 GB)."""
MAX_META_CHAIN = 8
"""Metadata headers in a row before a member (tarfile recurses through them)."""
MAX_ZIP_DIRECTORY = 64 << 20
"""Largest zip central directory (zipfile reads it whole): ~200 000 entries with 1 KiB names."""
_TAR_META = {
    tarfile.XHDTYPE, tarfile.XGLTYPE, tarfile.SOLARIS_XHDTYPE, tarfile.GNUTYPE_LONGNAME, tarfile.GNUTYPE_LONGLINK,
}


@dataclass(frozen=True, slots=True)
class Limits:
    max_files: int
    max_bytes: int
    """Largest unpacked total."""
    max_ratio: float
    """Largest unpacked/packed size ratio."""


@dataclass(frozen=True, slots=True)
class Unpacked:
    files: int
    size_bytes: int


def sniff(path: Path) -> str:
    """``"zip"``, ``"tar"`` (gzip-compressed or plain) by magic bytes; :class:`InvalidInput` otherwise."""
    with open(path, "rb") as fh:
        head = fh.read(512)
    if head[:4] in (b"PK\x03\x04", b"PK\x05\x06"):
        return "zip"
    if head[:2] == b"\x1f\x8b" or head[257:262] == b"ustar":
        return "tar"
    raise InvalidInput("the upload is not a .zip or .tar.gz archive", {"magic": head[:4].hex()})


def unpack(archive: Path, dest: Path, limits: Limits) -> Unpacked:
    """Extract ``archive`` into the existing empty folder ``dest``; raises before anything unsafe lands.

    On error ``dest`` may hold a partial extraction: the caller removes it (it is a staging folder).
    """
    kind = sniff(archive)
    packed = max(archive.stat().st_size, 1)
    budget = _Budget(limits, packed)
    if kind == "zip":
        _unpack_zip(archive, dest, budget)
    else:
        with open(archive, "rb") as raw:
            _unpack_tar(raw, dest, budget)
    if budget.files == 0:
        raise InvalidInput("the archive is empty")
    return Unpacked(budget.files, budget.bytes)


class _Budget:
    """Counts entries and unpacked bytes against the limits while they are written.

    ``packed`` is the archive's size, or a function giving the bytes consumed so far when the archive
    is unpacked while it streams in (then the ratio applies to what has arrived).
    """

    def __init__(self, limits: Limits, packed: int | Callable[[], int]) -> None:
        self.limits = limits
        self._packed = packed
        self.files = 0
        self.bytes = 0
        self.meta_chain = 0

    @property
    def packed(self) -> int:
        return self._packed() if callable(self._packed) else self._packed

    @property
    def max_bytes(self) -> int:
        """Small archives may always unpack to ``max_ratio`` MiB: the ratio guards against big bombs."""
        return min(self.limits.max_bytes, int(max(self.packed, RATIO_FLOOR) * self.limits.max_ratio))

    def meta(self, size: int) -> None:
        """A tar metadata header of ``size`` bytes, checked before its data is read."""
        self.meta_chain += 1
        if size > MAX_META_BYTES:
            raise PayloadTooLarge(
                f"an archive header (PAX or GNU long name) holds {size} bytes; at most {MAX_META_BYTES}",
                {"max_header_bytes": MAX_META_BYTES},
            )
        if self.meta_chain > MAX_META_CHAIN:
            raise InvalidInput(f"more than {MAX_META_CHAIN} metadata headers in a row in the archive")
        self.add(size)

    def entry(self) -> None:
        self.files += 1
        if self.files > self.limits.max_files:
            raise PayloadTooLarge(
                f"the archive holds more than {self.limits.max_files} entries",
                {"max_files": self.limits.max_files},
            )

    def add(self, n: int) -> None:
        self.bytes += n
        self.check()

    def check(self) -> None:
        if self.bytes <= self.max_bytes:
            return
        if self.bytes > self.limits.max_bytes:
            raise PayloadTooLarge(
                f"the archive unpacks to more than {self.limits.max_bytes} bytes",
                {"max_unpacked_bytes": self.limits.max_bytes},
            )
        raise PayloadTooLarge(
            f"the archive unpacks to more than {self.limits.max_ratio:g} times its size "
            "(a compression bomb?)",
            {"max_ratio": self.limits.max_ratio, "packed_bytes": self.packed},
        )


def safe_relpath(name: str) -> PurePosixPath | None:
    """The entry's path below the extraction root; None for entries to skip; InvalidInput if unsafe."""
    if "\x00" in name or len(name) > MAX_NAME_LEN:
        raise InvalidInput("an archive entry has an invalid name", {"entry": name[:200]})
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        raise InvalidInput(
            "an archive entry's name is not UTF-8", {"entry": name.encode("utf-8", "replace").decode()}
        ) from None
    if "\\" in name:
        raise InvalidInput("an archive entry's name contains a backslash", {"entry": name})
    if name.startswith("/") or (len(name) > 1 and name[1] == ":"):
        raise InvalidInput("an archive entry has an absolute path", {"entry": name})
    parts = [p for p in name.split("/") if p not in ("", ".")]
    if ".." in parts:
        raise InvalidInput("an archive entry's path contains '..'", {"entry": name})
    if not parts or parts[0] in SKIPPED_TOP:
        return None
    return PurePosixPath(*parts)


def _zip_name(info: zipfile.ZipInfo) -> str:
    """The entry's name; names without the UTF-8 flag must still be UTF-8 (cp437 round trip)."""
    name = info.filename
    if info.flag_bits & 0x800 or name.isascii():
        return name
    try:
        return name.encode("cp437").decode("utf-8")
    except (UnicodeEncodeError, UnicodeDecodeError):
        raise InvalidInput("an archive entry's name is not UTF-8", {"entry": name}) from None


def _zip_directory(archive: Path) -> tuple[int, int]:
    """(entries, central directory bytes) from the end records, read before zipfile loads the directory.

    (0, 0) when no end record is found: zipfile then refuses the file itself.
    """
    size = archive.stat().st_size
    with open(archive, "rb") as fh:
        fh.seek(max(0, size - (1 << 16) - 22))
        tail = fh.read()
        at = tail.rfind(b"PK\x05\x06")
        if at < 0 or len(tail) - at < 22:
            return 0, 0
        _sig, _d, _dcd, _n, entries, cd_size, _off, _c = struct.unpack("<4s4H2LH", tail[at : at + 22])
        loc = at - 20
        if (entries == 0xFFFF or cd_size == 0xFFFFFFFF) and loc >= 0 and tail[loc : loc + 4] == b"PK\x06\x07":
            (z64_at,) = struct.unpack("<Q", tail[loc + 8 : loc + 16])
            fh.seek(z64_at)
            rec = fh.read(56)
            if len(rec) == 56 and rec[:4] == b"PK\x06\x06":
                entries, cd_size = struct.unpack("<Q", rec[32:40])[0], struct.unpack("<Q", rec[40:48])[0]
    return entries, cd_size


def _unpack_zip(archive: Path, dest: Path, budget: _Budget) -> None:
    entries, directory = _zip_directory(archive)
    if entries > budget.limits.max_files:
        budget.files = entries - 1
        budget.entry()  # fails with the entry-count message
    if directory > MAX_ZIP_DIRECTORY:
        raise PayloadTooLarge(
            f"the zip's directory (names, extra fields, comments) is larger than {MAX_ZIP_DIRECTORY} bytes",
            {"max_directory_bytes": MAX_ZIP_DIRECTORY},
        )
    budget.add(directory)  # names, extra fields and comments are unpacked bytes too
    try:
        zf = zipfile.ZipFile(archive)
    except UnicodeDecodeError:
        raise InvalidInput("an archive entry's name is not UTF-8 (though flagged so)") from None
    except (zipfile.BadZipFile, ValueError) as exc:
        raise InvalidInput(f"not a readable zip archive: {exc}") from None
    with zf:
        infos = zf.infolist()
        for info in infos:  # every header is checked before anything is written
            budget.entry()
            rel = safe_relpath(_zip_name(info))
            ftype = stat.S_IFMT(info.external_attr >> 16)  # 0: no Unix type recorded (DOS-made zips)
            if ftype not in (0, stat.S_IFREG, stat.S_IFDIR):
                raise InvalidInput(
                    "archive entries must be regular files or folders (links and devices are refused)",
                    {"entry": info.filename},
                )
            if info.flag_bits & 0x1:
                raise InvalidInput("encrypted zip entries are not supported", {"entry": info.filename})
            if rel is not None and not info.is_dir() and info.file_size > budget.max_bytes:
                budget.add(info.file_size)  # fails with the right message before extracting
        declared = budget.bytes + sum(i.file_size for i in infos)
        if declared > budget.max_bytes:
            budget.add(declared - budget.bytes)
        budget.files = 0
        for info in infos:
            budget.entry()
            rel = safe_relpath(_zip_name(info))
            if rel is None:
                continue
            if info.is_dir():
                _mkdir(dest, rel)
                continue
            try:
                with zf.open(info) as src:
                    _write(dest, rel, src, budget)
            except (zipfile.BadZipFile, EOFError, zlib.error, NotImplementedError) as exc:
                raise InvalidInput(f"corrupt zip entry: {exc}", {"entry": info.filename}) from None


def unpack_tar_stream(fileobj: IO[bytes], dest: Path, limits: Limits, consumed: Callable[[], int]) -> Unpacked:
    """Extract a .tar.gz (or .tar) while it is read from ``fileobj`` (an upload still arriving).

    ``consumed()`` gives the archive bytes read so far: the compression ratio is checked against it.
    """
    budget = _Budget(limits, consumed)
    _unpack_tar(fileobj, dest, budget)
    budget.check()
    if budget.files == 0:
        raise InvalidInput("the archive is empty")
    return Unpacked(budget.files, budget.bytes)


def _budgeted_tarinfo(budget: _Budget) -> type[tarfile.TarInfo]:
    """A TarInfo that checks metadata headers before tarfile reads their data into memory."""

    class BudgetedTarInfo(tarfile.TarInfo):
        def _proc_member(self, tf: tarfile.TarFile) -> tarfile.TarInfo:
            if self.type in _TAR_META:
                budget.meta(self.size)
            elif self.type == tarfile.GNUTYPE_SPARSE:  # its extension blocks are read without bound
                raise InvalidInput("sparse archive entries are not supported", {"entry": self.name[:200]})
            else:
                budget.meta_chain = 0
            return super()._proc_member(tf)  # type: ignore[misc]

    return BudgetedTarInfo


def _unpack_tar(raw: IO[bytes], dest: Path, budget: _Budget) -> None:
    try:
        with tarfile.open(fileobj=raw, mode="r|*", tarinfo=_budgeted_tarinfo(budget)) as tf:
            for member in tf:  # streaming: headers are checked as they come, before their data
                budget.entry()
                rel = safe_relpath(member.name)
                if not (member.isreg() or member.isdir()):
                    raise InvalidInput(
                        "archive entries must be regular files or folders (links and devices are refused)",
                        {"entry": member.name},
                    )
                if rel is None:
                    continue
                if member.isdir():
                    _mkdir(dest, rel)
                    continue
                if member.size > budget.limits.max_bytes:  # the ratio is checked as bytes arrive
                    budget.add(member.size)
                src = tf.extractfile(member)
                assert src is not None  # regular files always have data
                _write(dest, rel, src, budget)
    except (tarfile.TarError, EOFError, zlib.error, gzip.BadGzipFile) as exc:
        raise InvalidInput(f"not a readable .tar.gz archive: {exc}") from None
    except RecursionError:  # headers tarfile follows recursively, beyond what MAX_META_CHAIN catches
        raise InvalidInput("the archive's headers are nested too deeply") from None


_NAME_ERRNOS = {errno.ENAMETOOLONG, errno.EILSEQ, errno.EINVAL}
"""What a filesystem answers to a name it refuses; anything else (a full disk, …) stays a server error."""


def _unusable(rel: PurePosixPath, exc: OSError) -> BaseException:
    """A name this filesystem refuses (a component over 255 bytes, …) is the archive's fault, not ours."""
    if exc.errno not in _NAME_ERRNOS:
        return exc
    return InvalidInput(
        f"an archive entry's name cannot be stored: {exc.strerror or exc}", {"entry": str(rel)[:200]}
    )


def _mkdir(dest: Path, rel: PurePosixPath) -> None:
    target = dest.joinpath(*rel.parts)
    try:
        if target.exists() and not target.is_dir():
            raise InvalidInput("an archive entry is both a file and a folder", {"entry": str(rel)})
        target.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):  # the folder, or one of its parents, is a file
        raise InvalidInput("an archive entry is both a file and a folder", {"entry": str(rel)}) from None
    except OSError as exc:
        raise _unusable(rel, exc) from None


def _write(dest: Path, rel: PurePosixPath, src: IO[bytes], budget: _Budget) -> None:
    target = dest.joinpath(*rel.parts)
    if rel.parent.parts:
        _mkdir(dest, rel.parent)
    try:
        # O_EXCL: a duplicated entry cannot overwrite an earlier one; O_NOFOLLOW: never through a link.
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
    except FileExistsError:
        raise InvalidInput("the archive has a duplicate entry", {"entry": str(rel)}) from None
    except (IsADirectoryError, NotADirectoryError):
        raise InvalidInput("an archive entry is both a file and a folder", {"entry": str(rel)}) from None
    except OSError as exc:
        raise _unusable(rel, exc) from None
    with os.fdopen(fd, "wb") as out:
        while chunk := src.read(CHUNK):
            budget.add(len(chunk))
            out.write(chunk)


def find_root(folder: Path) -> Path:
    """The sequence folder inside an unpacked archive: the folder itself or its one top-level folder."""
    if (folder / "rgb.txt").is_file():
        return folder
    entries = [p for p in folder.iterdir() if p.name not in SKIPPED_TOP and not p.name.startswith(".")]
    if len(entries) == 1 and entries[0].is_dir() and (entries[0] / "rgb.txt").is_file():
        return entries[0]
    raise InvalidInput(
        "no TUM-layout sequence in the archive: rgb.txt must be at its top level or in its one top-level folder",
        {"top_level": sorted(p.name for p in entries)[:20]},
    )


def remove_tree(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)
