"""Archive metadata counts against the limits: tar PAX / GNU long-name headers are checked before tarfile
reads them (the 408 KB PAX bomb is refused with memory flat), header chains and sparse entries are
refused, a zip's central directory (names, extra fields, comments) is counted and capped."""
from __future__ import annotations

import io
import tarfile
import tracemalloc
from pathlib import Path

import pytest

from storage.errors import InvalidInput, PayloadTooLarge
from storage.ingest.archive import MAX_META_BYTES, MAX_META_CHAIN, Limits, unpack, unpack_tar_stream
from tests.storage.ingest.bombs import header_bomb, pax_chain, sparse_tar, zip_with_metadata

LIMITS = Limits(max_files=1000, max_bytes=8 << 20, max_ratio=5)


def _stream(data: bytes, dest: Path, limits: Limits = LIMITS) -> None:
    dest.mkdir(parents=True, exist_ok=True)
    unpack_tar_stream(io.BytesIO(data), dest, limits, lambda: len(data))


@pytest.mark.parametrize("kind", [tarfile.XHDTYPE, tarfile.GNUTYPE_LONGNAME])
def test_a_400_mib_header_in_a_408_kb_upload_is_refused_with_memory_flat(tmp_path, kind) -> None:
    bomb = header_bomb(kind, 400 << 20)
    assert len(bomb) < 420_000
    tracemalloc.start()
    try:
        with pytest.raises(PayloadTooLarge, match="PAX or GNU long name"):
            _stream(bomb, tmp_path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100 << 20, f"{peak / 1e6:.0f} MB"  # was 400 MB plus copies
    (tmp_path / "a.tgz").write_bytes(bomb)
    with pytest.raises(PayloadTooLarge):  # the same through the archive-on-disk path
        unpack(tmp_path / "a.tgz", tmp_path / "out", LIMITS)


def test_headers_within_the_limit_still_unpack(tmp_path) -> None:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz", format=tarfile.PAX_FORMAT) as tf:
        name = "/".join(["d" * 100] * 3) + ".txt"  # needs a PAX header; well under MAX_META_BYTES
        info = tarfile.TarInfo(name)
        info.size = 2
        tf.addfile(info, io.BytesIO(b"ok"))
    _stream(buf.getvalue(), tmp_path)
    assert (tmp_path / name).read_bytes() == b"ok" and MAX_META_BYTES > 300


def test_header_chains_and_sparse_entries_are_refused(tmp_path) -> None:
    _stream(pax_chain(MAX_META_CHAIN), tmp_path / "ok")
    with pytest.raises(InvalidInput, match="metadata headers in a row"):
        _stream(pax_chain(MAX_META_CHAIN + 1), tmp_path / "chain")
    with pytest.raises(InvalidInput, match="metadata headers in a row"):
        _stream(pax_chain(3000), tmp_path / "deep")  # was a RecursionError (500)
    with pytest.raises(InvalidInput, match="sparse"):
        _stream(sparse_tar(), tmp_path / "sparse")


def test_zip_names_extra_fields_and_comments_count_against_the_limit(tmp_path) -> None:
    small = tmp_path / "small.zip"
    small.write_bytes(zip_with_metadata(entries=30, extra=0, comment=0))
    (tmp_path / "a").mkdir()
    assert unpack(small, tmp_path / "a", Limits(1000, 1 << 20, 1000)).files == 30
    heavy = tmp_path / "heavy.zip"  # 30 one-byte files, 3.6 MB of metadata
    heavy.write_bytes(zip_with_metadata(entries=30, extra=60_000, comment=60_000))
    (tmp_path / "b").mkdir()
    with pytest.raises(PayloadTooLarge, match="unpacks to more than"):
        unpack(heavy, tmp_path / "b", Limits(1000, 1 << 20, 1000))


def test_zip_entry_count_is_read_from_the_end_record_first(tmp_path) -> None:
    many = tmp_path / "many.zip"
    many.write_bytes(zip_with_metadata(entries=50, extra=0, comment=0))
    (tmp_path / "c").mkdir()
    with pytest.raises(PayloadTooLarge, match="more than 20 entries"):
        unpack(many, tmp_path / "c", Limits(20, 1 << 20, 1000))
