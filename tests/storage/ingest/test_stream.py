"""Unpacking while the upload arrives: same result as from a file, bombs and bad entries stop it early,
an aborted upload stops the unpacking thread."""
from __future__ import annotations

import io
import tarfile
import threading
import zipfile

import pytest

from storage.errors import InvalidInput, PayloadTooLarge
from storage.ingest.archive import Limits
from storage.ingest.stream import ArchiveSink

LIMITS = Limits(max_files=100, max_bytes=1 << 30, max_ratio=50)


def _tgz(files: dict[str, bytes], **entries: tarfile.TarInfo) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tf:
        for name, data in files.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))
        for info in entries.values():
            tf.addfile(info)
    return buf.getvalue()


def _feed(sink: ArchiveSink, data: bytes, block: int = 1000) -> None:
    for i in range(0, len(data), block):
        sink.write(data[i:i + block])
    sink.close()


def test_tgz_is_unpacked_while_streaming(tmp_path):
    files = {f"seq/f{i}.bin": bytes([i]) * 5000 for i in range(10)}
    sink = ArchiveSink(tmp_path, LIMITS)
    _feed(sink, _tgz(files))
    assert sink.streaming and not (tmp_path / "archive").exists()
    assert sink.unpacked is not None and sink.unpacked.files == 10
    assert (tmp_path / "unpacked/seq/f3.bin").read_bytes() == bytes([3]) * 5000


def test_zip_goes_to_a_file(tmp_path):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("a.txt", "x")
    sink = ArchiveSink(tmp_path, LIMITS)
    _feed(sink, buf.getvalue())
    assert not sink.streaming and (tmp_path / "archive").read_bytes() == buf.getvalue()


def test_a_bomb_stops_the_stream_early(tmp_path):
    bomb = _tgz({"seq/zeros.bin": bytes(200_000_000)})
    assert len(bomb) < 1_000_000
    sink = ArchiveSink(tmp_path, Limits(max_files=10, max_bytes=1 << 40, max_ratio=20))
    with pytest.raises(PayloadTooLarge, match="compression bomb"):
        _feed(sink, bomb, block=1 << 16)
    unpacked = sum(p.stat().st_size for p in (tmp_path / "unpacked").rglob("*") if p.is_file())
    assert unpacked <= 22 * (1 << 20)  # stopped near ratio x max(consumed, 1 MiB), not at 200 MB


def test_a_link_entry_fails_the_write_or_close(tmp_path):
    link = tarfile.TarInfo("seq/link")
    link.type, link.linkname = tarfile.SYMTYPE, "/etc/passwd"
    sink = ArchiveSink(tmp_path, LIMITS)
    with pytest.raises(InvalidInput, match="links"):
        _feed(sink, _tgz({"seq/a.txt": b"a"}, link=link))
    assert not (tmp_path / "unpacked/seq/link").exists()


def test_abort_mid_stream_ends_the_thread(tmp_path):
    data = _tgz({f"seq/f{i}.bin": bytes([i]) * 100_000 for i in range(20)})
    sink = ArchiveSink(tmp_path, LIMITS)
    sink.write(data[: len(data) // 2])
    sink.abort()
    assert not any(t.name == "unpack" and t.is_alive() for t in threading.enumerate())


def test_empty_upload_becomes_an_empty_archive_file(tmp_path):
    sink = ArchiveSink(tmp_path, LIMITS)
    sink.close()
    assert (tmp_path / "archive").read_bytes() == b""
