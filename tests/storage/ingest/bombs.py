"""Archives whose metadata, not their files, is the attack (made in code, compressed as they stream)."""
from __future__ import annotations

import io
import tarfile
import zipfile
import zlib


def _gz(blocks: list[bytes], zeros: int = 0) -> bytes:
    gz = zlib.compressobj(9, zlib.DEFLATED, 31)
    out = [gz.compress(b) for b in blocks]
    chunk = bytes(1 << 20)
    for _ in range(zeros >> 20):
        out.append(gz.compress(chunk))
    out.append(gz.compress(bytes(zeros & ((1 << 20) - 1))))
    out.append(gz.flush())
    return b"".join(out)


def header_bomb(kind: bytes, size: int) -> bytes:
    """A .tar.gz whose first header (PAX ``x`` or GNU long name ``L``) claims ``size`` bytes of zeros:
    400 MiB compress to ~408 KB, the upload that took the api from 157 MB to 1.67 GB."""
    info = tarfile.TarInfo("././@PaxHeader" if kind == tarfile.XHDTYPE else "././@LongLink")
    info.type, info.size = kind, size
    return _gz([info.tobuf(format=tarfile.USTAR_FORMAT)], zeros=size)


def pax_chain(n: int) -> bytes:
    """``n`` small PAX headers in a row before one file (tarfile follows them recursively)."""
    blocks = []
    for i in range(n):
        record = f"{len(f'  comment={i}') + 5} comment={i}\n".encode()
        info = tarfile.TarInfo("././@PaxHeader")
        info.type, info.size = tarfile.XHDTYPE, len(record)
        blocks += [info.tobuf(format=tarfile.USTAR_FORMAT), record + bytes(-len(record) % 512)]
    f = tarfile.TarInfo("rgb.txt")
    f.size = 3
    blocks += [f.tobuf(format=tarfile.USTAR_FORMAT), b"abc" + bytes(509), bytes(1024)]
    return _gz(blocks)


def sparse_tar() -> bytes:
    info = tarfile.TarInfo("rgb.txt")
    info.type, info.size = tarfile.GNUTYPE_SPARSE, 0
    return _gz([info.tobuf(format=tarfile.GNU_FORMAT), bytes(1024)])


def zip_with_metadata(entries: int, extra: int, comment: int) -> bytes:
    """Tiny files whose names, extra fields and comments are most of the archive."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        for i in range(entries):
            info = zipfile.ZipInfo(f"f{i:05d}.txt")
            info.extra = (b"\xfe\xca" + (extra - 4).to_bytes(2, "little") + bytes(extra - 4)) if extra else b""
            info.comment = b"c" * comment
            zf.writestr(info, b"x")
    return buf.getvalue()
