"""Hostile uploads, table-driven: every one a clear 4xx (413 for size limits) in the api's error shape, and
nothing left behind — no sequence row, nothing under the data dir but the database and empty folders.

The corpus is made here, in code: path traversal and links in zip and tar, zip and tar bombs, too many
files, broken or huge images, bad layouts, non-UTF-8 names, truncated archives, the wrong file type and
broken multipart bodies. Limits are set small through Settings so the size cases stay fast. An upload
cut off mid-stream is sent to a real uvicorn server through a raw socket.
"""
from __future__ import annotations

import gzip
import io
import shutil
import socket
import struct
import tarfile
import threading
import time
import tracemalloc
import warnings
import zipfile
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import uvicorn
from fastapi.testclient import TestClient
from starlette.types import Message, Scope

from backend.app import create_app
from storage.settings import Settings, get_settings
from tests.backend.api.conftest import upload
from tests.backend.api.data import tar_gz, tar_with, zip_of

LIMITS: dict[str, Any] = {"max_upload_bytes": 2 << 20, "max_files": 1000, "max_ratio": 5}
"""Uploads up to 2 MiB, unpacked up to 5x max(archive, 1 MiB), 1000 entries: the valid sequence fits."""
BOMB = 7_000_000
"""Zeros (~7 kB deflated): past the ratio limit (5 MiB for a small archive), under the total (8 MiB)."""


# ---- what "nothing left behind" means ----------------------------------------------------------------

def residue(data_dir: Path) -> list[str]:
    """Everything under the data dir except the database/queue files and empty container folders."""
    out = []
    for p in sorted(data_dir.rglob("*")):
        rel = p.relative_to(data_dir).as_posix()
        if p.is_file() and p.name.startswith(("vtdslam.db", "queue.db")):
            continue
        if p.is_dir() and rel in ("staging", "sequences", "artifacts") and not any(p.iterdir()):
            continue
        out.append(rel)
    return out


def assert_clean_rejection(client: TestClient, settings: Settings, r: Any, status: int, fragment: str) -> None:
    assert r.status_code == status, r.text[:500]
    body = r.json()
    assert set(body) == {"error"} and set(body["error"]) == {"code", "message", "detail", "request_id"}, body
    assert body["error"]["code"] == {413: "payload_too_large", 422: "invalid_input"}[status]
    assert fragment in body["error"]["message"], body["error"]["message"]
    listing = client.get("/api/v1/sequences").json()
    assert listing["items"] == [] and listing["total"] == 0
    assert residue(settings.data_dir) == []


# ---- corpus builders: each gets a scratch dir and a valid sequence folder, returns (filename, bytes) ----

Build = Callable[[Path, Path], tuple[str, bytes]]


def _entry(name: str, kind: bytes = tarfile.REGTYPE, **kw: Any) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.type = kind
    for k, v in kw.items():
        setattr(info, k, v)
    return info


def _zip(entries: Sequence[tuple[str | zipfile.ZipInfo, bytes]], method: int = zipfile.ZIP_DEFLATED) -> bytes:
    buf = io.BytesIO()
    with warnings.catch_warnings(), zipfile.ZipFile(buf, "w", method) as zf:
        warnings.simplefilter("ignore")  # duplicate names
        for name, data in entries:
            zf.writestr(name, data)
    return buf.getvalue()


def _zip_link(name: str, target: str) -> bytes:
    info = zipfile.ZipInfo(name)
    info.external_attr = 0o120777 << 16  # S_IFLNK: how Info-ZIP stores a symlink (the data is the target)
    info.create_system = 3  # Unix
    return _zip([(info, target.encode())])


def _tgz_of(folder: Path, scratch: Path) -> bytes:
    return tar_gz(folder, scratch / "seq.tgz", top="seq").read_bytes()


def _broken(breaker: Callable[[Path], None]) -> Build:
    def build(scratch: Path, seq: Path) -> tuple[str, bytes]:
        folder = shutil.copytree(seq, scratch / "broken")
        breaker(folder)
        return "broken.tgz", _tgz_of(folder, scratch)

    return build


def _frames(folder: Path, kind: str) -> list[Path]:
    return sorted((folder / kind).iterdir())


def _png(width: int, height: int, depth: int, color: int, idat: bytes) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, depth, color, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


def _flip_byte(folder: Path) -> None:
    p = _frames(folder, "rgb")[0]
    data = bytearray(p.read_bytes())
    data[60] ^= 0xFF
    p.write_bytes(bytes(data))


def _truncate_png(folder: Path) -> None:
    p = _frames(folder, "rgb")[0]
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])


def _huge_header(folder: Path) -> None:
    """A 30000x30000 RGB header (2.7 GB of pixels) over a few bytes of data: a decompression bomb."""
    _frames(folder, "rgb")[0].write_bytes(_png(30000, 30000, 8, 2, zlib.compress(b"\0" * 1000)))


def _png_zlib_bomb(folder: Path) -> None:
    """An honest 160x120 header over a zlib stream that inflates to 50 MB."""
    _frames(folder, "rgb")[0].write_bytes(_png(160, 120, 8, 2, zlib.compress(bytes(50_000_000), 9)))


def _depth_8bit(folder: Path) -> None:
    for p in _frames(folder, "depth"):
        cv2.imwrite(str(p), np.full((120, 160), 50, np.uint8))


def _mismatched_sizes(folder: Path) -> None:
    for p in _frames(folder, "depth"):
        cv2.imwrite(str(p), np.full((60, 80), 5000, np.uint16))


def _list_line(line: str) -> Callable[[Path], None]:
    def breaker(folder: Path) -> None:
        (folder / "rgb.txt").write_text(line + "\n")

    return breaker


def _zip_renamed(old: bytes, new: bytes, entries: list[tuple[str, bytes]]) -> bytes:
    """Raw name bytes a zip writer would never produce (same length, so every offset still holds)."""
    data = _zip(entries)
    assert len(old) == len(new) and data.count(old) == 2  # local header and central directory
    return data.replace(old, new)


def _zip_flags(data: bytes, flag: int) -> bytes:
    """Set a general-purpose flag bit in every local and central header."""
    out = bytearray(data)
    for sig, off in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):
        i = out.find(sig)
        while i >= 0:
            (bits,) = struct.unpack_from("<H", out, i + off)
            struct.pack_into("<H", out, i + off, bits | flag)
            i = out.find(sig, i + 4)
    return bytes(out)


def _many(n: int, kind: str) -> Build:
    def build(scratch: Path, seq: Path) -> tuple[str, bytes]:
        names = [f"seq/f{i:05d}.txt" for i in range(n)]
        if kind == "zip":
            return "many.zip", _zip([(name, b"x") for name in names], zipfile.ZIP_STORED)
        return "many.tgz", tar_with([_entry(name) for name in names], {name: b"x" for name in names})

    return build


def _bomb(kind: str) -> Build:
    def build(scratch: Path, seq: Path) -> tuple[str, bytes]:
        if kind == "zip":
            return "bomb.zip", _zip([("seq/rgb.txt", bytes(BOMB))])
        return "bomb.tgz", tar_with([_entry("seq/rgb.txt")], {"seq/rgb.txt": bytes(BOMB)})

    return build


def _truncated(kind: str) -> Build:
    def build(scratch: Path, seq: Path) -> tuple[str, bytes]:
        if kind == "zip":
            data = zip_of(seq, scratch / "s.zip").read_bytes()
            return "cut.zip", data[: len(data) * 2 // 3]  # the central directory is gone
        data = _tgz_of(seq, scratch)
        return "cut.tgz", data[: len(data) * 2 // 3]

    return build


def _const(filename: str, data: bytes) -> Build:
    return lambda scratch, seq: (filename, data)


@dataclass(frozen=True)
class Case:
    build: Build
    status: int
    fragment: str
    settings: dict[str, Any] = field(default_factory=dict)


LONG = "a" * 300  # one path component over NAME_MAX (255)
CORPUS: dict[str, Case] = {
    # path traversal and links
    "zip slip ../x": Case(_const("s.zip", _zip([("../x", b"x")])), 422, "'..'"),
    "zip slip nested": Case(_const("s.zip", _zip([("seq/../../x", b"x")])), 422, "'..'"),
    "zip absolute path": Case(_const("s.zip", _zip([("/tmp/vtd-evil", b"x")])), 422, "absolute path"),
    "zip drive letter": Case(_const("s.zip", _zip([("C:/evil", b"x")])), 422, "absolute path"),
    "zip backslash traversal": Case(_const("s.zip", _zip([("seq\\..\\..\\x", b"x")])), 422, "backslash"),
    "zip symlink (external_attr)": Case(_const("s.zip", _zip_link("seq/rgb.txt", "/etc/passwd")), 422, "links"),
    "tar slip ../x": Case(_const("s.tgz", tar_with([_entry("../x")], {"../x": b"x"})), 422, "'..'"),
    "tar absolute path": Case(_const("s.tgz", tar_with([_entry("/tmp/vtd-evil")], {"/tmp/vtd-evil": b"x"})),
                              422, "absolute path"),
    "tar symlink": Case(_const("s.tgz", tar_with([_entry("seq/l", tarfile.SYMTYPE, linkname="/etc")])),
                        422, "links"),
    "tar symlink then write through it": Case(_const("s.tgz", tar_with(
        [_entry("seq/d", tarfile.SYMTYPE, linkname="/tmp"), _entry("seq/d/vtd-evil")], {"seq/d/vtd-evil": b"x"})),
        422, "links"),
    "tar hard link": Case(_const("s.tgz", tar_with([_entry("seq/h", tarfile.LNKTYPE, linkname="/etc/passwd")])),
                          422, "links"),
    "tar device": Case(_const("s.tgz", tar_with([_entry("seq/d", tarfile.CHRTYPE, devmajor=1, devminor=3)])),
                       422, "devices"),
    "tar fifo": Case(_const("s.tgz", tar_with([_entry("seq/f", tarfile.FIFOTYPE)])), 422, "devices"),
    # sizes: 413
    "zip bomb (ratio)": Case(_bomb("zip"), 413, "compression bomb"),
    "tar bomb (ratio)": Case(_bomb("tgz"), 413, "compression bomb"),
    "zip bomb (total)": Case(_bomb("zip"), 413, "unpacks to more than 1048576 bytes",
                             {"max_upload_bytes": 256 << 10, "max_ratio": 10_000}),
    "tar bomb (total)": Case(_bomb("tgz"), 413, "unpacks to more than 1048576 bytes",
                             {"max_upload_bytes": 256 << 10, "max_ratio": 10_000}),
    "zip with 3000 tiny files": Case(_many(3000, "zip"), 413, "more than 1000 entries"),
    "tar with 3000 tiny files": Case(_many(3000, "tgz"), 413, "more than 1000 entries"),
    "upload over max_upload_bytes": Case(_const("big.zip", np.random.default_rng(0).bytes(3 << 20)), 413,
                                         "larger than"),
    # images
    "corrupt png": Case(_broken(_flip_byte), 422, "corrupt"),
    "truncated png": Case(_broken(_truncate_png), 422, "truncated"),
    "30000x30000 png header": Case(_broken(_huge_header), 422,  # the folder kept, the limit stated
                                    "rgb/100.000000.png: image is too large (30000x30000 = 900000000 pixels; "
                                    "the limit is 16777216 pixels"),
    "png zlib bomb": Case(_broken(_png_zlib_bomb), 422, "larger than its header says"),
    "8-bit depth": Case(_broken(_depth_8bit), 422, "16-bit single-channel PNG"),
    "mismatched image sizes": Case(_broken(_mismatched_sizes), 422, "depth is 80x60 but colour is 160x120"),
    # layout and list files
    "missing rgb.txt": Case(_broken(lambda f: (f / "rgb.txt").unlink()), 422, "no TUM-layout sequence"),
    "rgb.txt lists a NUL path": Case(_broken(_list_line("1.0 rgb/\x00.png")), 422, "must be relative"),
    "rgb.txt lists a 300-char name": Case(_broken(_list_line(f"1.0 rgb/{LONG}.png")), 422, "unusable"),
    "rgb.txt lists /etc/passwd": Case(_broken(_list_line("1.0 /etc/passwd")), 422, "must be relative"),
    # names
    "zip non-UTF-8 name (unflagged)": Case(_const("s.zip", _zip_renamed(
        b"XX", b"\xff\xfe", [("seq/XX.png", b"x")])), 422, "not UTF-8"),
    "zip non-UTF-8 name (flagged UTF-8)": Case(_const("s.zip", _zip_renamed(
        "\u00e9".encode(), b"\xe9\x20", [("seq/\u00e9.png", b"x")])), 422, "not UTF-8"),
    "tar non-UTF-8 name": Case(_const("s.tgz", tar_with([_entry("seq/\udcff.png")], {"seq/\udcff.png": b"x"})),
                               422, "not UTF-8"),
    "zip 300-char name": Case(_const("s.zip", _zip([(f"seq/{LONG}.png", b"x")])), 422, "cannot be stored"),
    "tar 300-char folder": Case(_const("s.tgz", tar_with([_entry(f"seq/{LONG}/x")], {f"seq/{LONG}/x": b"x"})),
                                422, "cannot be stored"),
    "tar 2000-char name": Case(_const("s.tgz", tar_with([_entry("a/" * 1000)])), 422, "invalid name"),
    # broken containers and wrong types
    "truncated zip": Case(_truncated("zip"), 422, "not a readable zip"),
    "truncated tar.gz": Case(_truncated("tgz"), 422, "not a readable .tar.gz"),
    "gzip that is not a tar": Case(_const("s.tgz", gzip.compress(b"just text, no tar header" * 40)), 422,
                                   "not a readable .tar.gz"),
    "encrypted zip entry": Case(_const("s.zip", _zip_flags(_zip([("seq/rgb.txt", b"x")]), 0x1)), 422, "encrypted"),
    "a .txt called .zip": Case(_const("seq.zip", b"timestamp filename\n1.0 rgb/x.png\n" * 20), 422,
                               "not a .zip or .tar.gz"),
    "an empty file": Case(_const("seq.zip", b""), 422, "not a .zip or .tar.gz"),
    "an empty zip": Case(_const("s.zip", _zip([])), 422, "empty"),
}


@pytest.fixture
def make_client(tmp_path: Path) -> Iterator[Callable[..., tuple[TestClient, Settings]]]:
    clients: list[TestClient] = []

    def make(**overrides: Any) -> tuple[TestClient, Settings]:
        settings = get_settings(data_dir=tmp_path / "data", **{**LIMITS, **overrides})
        client = TestClient(create_app(settings, enqueue=lambda _id: None))
        clients.append(client.__enter__())
        return client, settings

    yield make
    for c in clients:
        c.__exit__(None, None, None)


def test_the_limits_accept_a_valid_sequence(make_client, seq_tgz, seq_folder, tmp_path) -> None:
    """The control: under the corpus's small limits a real sequence still goes in (tgz and zip)."""
    client, _ = make_client()
    assert upload(client, seq_tgz).status_code == 201
    r = upload(client, zip_of(seq_folder, tmp_path / "s.zip").read_bytes(), filename="s.zip")
    assert r.status_code == 201, r.text


@pytest.mark.parametrize("name", list(CORPUS))
def test_hostile_upload_is_rejected_cleanly(name: str, make_client, seq_folder, tmp_path) -> None:
    case = CORPUS[name]
    client, settings = make_client(**case.settings)
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    filename, data = case.build(scratch, seq_folder)
    tracemalloc.start()  # the api runs in this process: its allocations are counted
    try:
        r = upload(client, data, filename=filename)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert_clean_rejection(client, settings, r, case.status, case.fragment)
    assert peak < 100 << 20, f"the api's memory grew by {peak / 1e6:.0f} MB"
    assert not Path("/tmp/vtd-evil").exists() and not (tmp_path / "x").exists()


def test_chunked_upload_over_the_limit_is_413(make_client) -> None:
    """No Content-Length to refuse up front: the bytes are counted as they arrive."""
    client, settings = make_client(max_upload_bytes=1 << 20)
    boundary = "vtdboundary"
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"camera\"\r\n\r\ntum1\r\n"
            f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"s.tgz\"\r\n\r\n").encode()

    def body() -> Iterator[bytes]:
        yield head + b"\x1f\x8b"  # looks like gzip: unpacked while streaming
        for _ in range(40):
            yield bytes(64 << 10)

    r = client.post("/api/v1/sequences", content=body(),
                    headers={"content-type": f"multipart/form-data; boundary={boundary}"})
    assert_clean_rejection(client, settings, r, 413, "larger than 1048576 bytes")


@pytest.mark.parametrize("form, fragment", [
    ({f"f{i}": "x" for i in range(30)}, "too many form fields"),
    ({"camera": "tum1", "name": "x" * 70_000}, "is too long"),
])
def test_hostile_form_fields(make_client, seq_tgz, form, fragment) -> None:
    client, settings = make_client()
    r = client.post("/api/v1/sequences", data=form, files={"file": ("s.tgz", seq_tgz)})
    assert_clean_rejection(client, settings, r, 422, fragment)


def test_two_file_parts(make_client, seq_tgz) -> None:
    client, settings = make_client()
    r = client.post("/api/v1/sequences", data={"camera": "tum1"},
                    files=[("file", ("a.tgz", seq_tgz)), ("file", ("b.tgz", seq_tgz))])
    assert_clean_rejection(client, settings, r, 422, "only one 'file' part")


def test_non_latin1_part_headers_are_not_a_500(make_client, seq_tgz) -> None:
    """Found by the fuzzer: a UTF-8 field name or filename made the multipart parser raise (500)."""
    client, settings = make_client()
    boundary = "b0undary"
    body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"\u0100\"\r\n\r\nx\r\n"
            f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"s.tgz\"\r\n\r\n"
            ).encode() + seq_tgz + f"\r\n--{boundary}--\r\n".encode()
    r = client.post("/api/v1/sequences", content=body,
                    headers={"content-type": f"multipart/form-data; boundary={boundary}"})
    assert_clean_rejection(client, settings, r, 422, "'camera' field")
    # a browser sends a non-ASCII file name as raw UTF-8: accepted, and the name survives
    r = upload(client, seq_tgz, filename="donn\u00e9es-\u0100.tgz")
    assert r.status_code == 201, r.text
    assert r.json()["name"] == "donn\u00e9es-\u0100"


# ---- an upload cut off mid-stream, against a real server -----------------------------------------------

@pytest.fixture
def live_server(tmp_path: Path) -> Iterator[tuple[int, Settings]]:
    """uvicorn in a thread on a free loopback port (a pre-bound socket: no race for the port)."""
    settings = get_settings(data_dir=tmp_path / "live", **{**LIMITS, "max_upload_bytes": 64 << 20})
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    config = uvicorn.Config(create_app(settings, enqueue=lambda _id: None), log_level="warning", lifespan="on")
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not server.started:
        assert time.monotonic() < deadline and thread.is_alive(), "uvicorn did not start"
        time.sleep(0.02)
    yield sock.getsockname()[1], settings
    server.should_exit = True
    thread.join(10)
    sock.close()


def _get(port: int, path: str) -> tuple[int, bytes]:
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(f"GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".encode())
        data = b""
        while chunk := s.recv(65536):
            data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    return int(head.split()[1]), body


@pytest.mark.parametrize("kind", ["tgz", "zip"])
def test_upload_cut_off_mid_stream_leaves_nothing(live_server, tmp_path, kind) -> None:
    """The client announces 6 MB, sends 5 MB (past the 4 MiB block: a tgz is being unpacked by then,
    a zip written to staging) and closes. The server must drop all of it and keep serving."""
    port, settings = live_server
    payload = np.random.default_rng(1).bytes(6 << 20)  # incompressible: the archive stays ~6 MB
    if kind == "tgz":
        archive = tar_with([_entry("seq/blob.bin")], {"seq/blob.bin": payload})
    else:
        archive = _zip([("seq/blob.bin", payload)], zipfile.ZIP_STORED)
    boundary = "cutboundary"
    body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"camera\"\r\n\r\ntum1\r\n"
            f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"s.{kind}\"\r\n\r\n"
            ).encode() + archive + f"\r\n--{boundary}--\r\n".encode()
    head = (f"POST /api/v1/sequences HTTP/1.1\r\nHost: x\r\nContent-Length: {len(body)}\r\n"
            f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n").encode()
    staging = settings.data_dir / "staging"
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(head + body[: 5 << 20])
        deadline = time.monotonic() + 10  # the upload is in flight: its staging folder exists
        while not (staging.is_dir() and any(staging.iterdir())):
            assert time.monotonic() < deadline, "the server never started staging the upload"
            time.sleep(0.02)
    deadline = time.monotonic() + 20
    while residue(settings.data_dir):
        assert time.monotonic() < deadline, residue(settings.data_dir)
        time.sleep(0.05)
    status, listing = _get(port, "/api/v1/sequences")
    assert status == 200 and b'"total":0' in listing and b'"items":[]' in listing
    assert _get(port, "/api/v1/health")[0] == 200  # still serving


def test_disconnect_mid_upload_is_a_clear_422() -> None:
    """What the app answers when the body stops with http.disconnect (the socket test cannot read it)."""
    import asyncio
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        settings = get_settings(data_dir=Path(tmp) / "data", **LIMITS)
        app = create_app(settings, enqueue=lambda _id: None)
        boundary = "b"
        part = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"s.tgz\"\r\n\r\n"
                ).encode() + b"\x1f\x8b" + bytes(1000)
        messages: list[Message] = [{"type": "http.request", "body": part, "more_body": True},
                                    {"type": "http.disconnect"}]
        sent: list[Message] = []

        async def receive() -> Message:
            return messages.pop(0) if messages else {"type": "http.disconnect"}

        async def send(message: Message) -> None:
            sent.append(message)

        async def run() -> None:
            scope: Scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST",
                     "scheme": "http", "path": "/api/v1/sequences", "raw_path": b"/api/v1/sequences",
                     "root_path": "", "query_string": b"", "client": ("127.0.0.1", 1), "server": ("x", 80),
                     "headers": [(b"content-type", f"multipart/form-data; boundary={boundary}".encode()),
                                 (b"content-length", b"100000")]}
            await app(scope, receive, send)

        with TestClient(app):  # runs the lifespan (database schema)
            asyncio.run(run())
        start = next(m for m in sent if m["type"] == "http.response.start")
        body = b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")
        assert start["status"] == 422 and b"disconnected during the upload" in body
        assert residue(settings.data_dir) == []


@pytest.mark.parametrize("length", [257, 4000])
def test_an_overlong_multipart_boundary_is_422(make_client, seq_tgz, length: int) -> None:
    """Issue 60.2: python-multipart refuses boundaries over 256 characters when the parser is made (a 500)."""
    client, settings = make_client()
    boundary = "b" * length
    body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"camera\"\r\n\r\ntum1\r\n"
            f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"s.tgz\"\r\n\r\n"
            ).encode() + seq_tgz + f"\r\n--{boundary}--\r\n".encode()
    r = client.post("/api/v1/sequences", content=body,
                    headers={"content-type": f"multipart/form-data; boundary={boundary}"})
    assert_clean_rejection(client, settings, r, 422, "boundary")


@pytest.mark.parametrize("list_name", ["rgb.txt", "depth.txt"])
def test_repeated_timestamps_are_422_naming_file_and_line(make_client, seq_folder, tmp_path, list_name) -> None:
    """Issue 60.6: every line at the same time uploaded fine (duration 0) and made an unevaluable run."""
    client, settings = make_client()
    folder = tmp_path / "dup"
    shutil.copytree(seq_folder, folder)
    lines = (folder / list_name).read_text().splitlines()
    stamp = lines[1].split()[0]
    lines[3] = f"{stamp} {lines[3].split()[1]}"  # the third frame repeats the first one's timestamp
    (folder / list_name).write_text("\n".join(lines) + "\n")
    r = upload(client, tar_gz(folder, tmp_path / "dup.tgz").read_bytes())
    assert_clean_rejection(client, settings, r, 422, f"{list_name}:4: timestamp")
    assert "strictly increase" in r.json()["error"]["message"]
    assert r.json()["error"]["detail"] == {"file": list_name, "line": 4}
