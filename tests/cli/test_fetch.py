"""`vtdslam fetch` end to end against a local HTTP server (127.0.0.1, an ephemeral port) serving small
TUM-layout archives the tests make: fresh downloads, an interrupted download resumed with a Range request, a
server that ignores Range, corrupted and truncated archives refused with nothing unpacked, a sequence already
there skipped. Nothing here reaches beyond 127.0.0.1."""
from __future__ import annotations

import dataclasses
import gzip
import hashlib
import io
import json
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.fetch.catalog import DATASETS, TABLES, lookup
from cli.fetch.download import STAGING, FetchError, Interrupted, fetch
from cli.main import app
from tests.backend.api.data import tar_gz, write_sequence, zip_of

TUM = DATASETS["tum-fr3-walking-xyz"]
BONN = DATASETS["bonn-crowd"]


class Server:
    """Serves ``files`` (URL path -> bytes) with Range support; ``truncate`` cuts the next N answers of a path
    halfway (full Content-Length, half the body, connection closed); ``ignore_range`` answers 200 always."""

    def __init__(self) -> None:
        self.files: dict[str, bytes] = {}
        self.truncate: dict[str, int] = {}
        self.ignore_range = False
        self.requests: list[tuple[str, str | None]] = []
        server = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, *args: object) -> None:
                pass

            def do_GET(self) -> None:  # noqa: N802 - http.server's name
                rng = self.headers.get("Range")
                server.requests.append((self.path, rng))
                data = server.files.get(self.path)
                if data is None:
                    self.send_error(404)
                    return
                start = 0
                if rng and not server.ignore_range:
                    start = int(rng.removeprefix("bytes=").split("-")[0])
                    if start >= len(data):
                        self.send_response(416)
                        self.send_header("Content-Range", f"bytes */{len(data)}")
                        self.send_header("Content-Length", "0")
                        self.end_headers()
                        return
                    self.send_response(206)
                    self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
                else:
                    self.send_response(200)
                body = data[start:]
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Accept-Ranges", "bytes")
                self.end_headers()
                if server.truncate.get(self.path, 0) > 0:
                    server.truncate[self.path] -= 1
                    self.wfile.write(body[: len(body) // 2])
                    self.wfile.flush()
                    self.close_connection = True
                    return
                self.wfile.write(body)

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.base = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()

    def ranges(self, path: str) -> list[str | None]:
        return [r for p, r in self.requests if p == path]


@pytest.fixture
def server(monkeypatch: pytest.MonkeyPatch) -> Iterator[Server]:
    for var in ("http_proxy", "HTTP_PROXY", "https_proxy", "HTTPS_PROXY", "all_proxy", "ALL_PROXY"):
        monkeypatch.delenv(var, raising=False)
    srv = Server()
    yield srv
    srv.httpd.shutdown()
    srv.httpd.server_close()


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 640x480 three-frame TUM-layout sequence (no camera.json, like the official ones)."""
    return write_sequence(tmp_path_factory.mktemp("seq") / "seq", n=3, size=(640, 480), camera_json=False)


@pytest.fixture(scope="module")
def archives(sequence: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """The sequence as TUM's .tgz and Bonn's .zip (under their folders), and as a .tgz without a folder."""
    root = tmp_path_factory.mktemp("archives")
    return {"tgz": tar_gz(sequence, root / "a.tgz", top=TUM.folder).read_bytes(),
            "zip": zip_of(sequence, root / "a.zip", top=BONN.folder).read_bytes(),
            "flat": tar_gz(sequence, root / "flat.tgz", top=None).read_bytes()}


def _serve(server: Server, archives: dict[str, bytes], ds=TUM, kind: str = "tgz") -> str:
    path = "/" + ds.path
    server.files[path] = archives[kind]
    return path


def _nothing_half_done(to: Path, ds=TUM) -> None:
    assert not (to / ds.folder).exists()
    assert not [p for p in to.iterdir() if p.name.endswith(".unpacking")]


def test_fresh_tgz_download_unpacks_the_tum_layout_run_and_upload_accept(tmp_path, server, archives):
    from storage.ingest.sequence import read_camera_file, validate_sequence
    from worker.slam.io.sequence import Sequence

    path = _serve(server, archives)
    done = fetch(TUM, tmp_path, url_base=server.base)
    assert done.status == "downloaded" and done.folder == tmp_path / TUM.folder
    assert done.bytes == len(archives["tgz"]) and server.ranges(path) == [None]
    for name in ("rgb.txt", "depth.txt", "groundtruth.txt", "camera.json"):
        assert (done.folder / name).is_file()
    camera = json.loads((done.folder / "camera.json").read_text())
    assert camera["name"] == "tum3" and camera["fx"] == 535.4
    assert sorted(p.name for p in tmp_path.iterdir()) == [TUM.folder]  # no .part, no staging left
    info = validate_sequence(done.folder, read_camera_file(done.folder))  # the upload's checker
    assert info.frames == 3 and info.has_groundtruth
    assert len(Sequence(done.folder)) == 3  # what `vtdslam run` reads (its camera from camera.json)


def test_bonn_zip_keeps_the_official_layout(tmp_path, server, archives):
    _serve(server, archives, BONN, "zip")
    done = fetch(BONN, tmp_path, url_base=server.base)
    assert done.status == "downloaded" and (done.folder / "groundtruth.txt").is_file()
    assert json.loads((done.folder / "camera.json").read_text())["name"] == "bonn"


def test_interrupted_download_resumes_with_a_range_request(tmp_path, server, archives):
    path = _serve(server, archives)
    server.truncate[path] = 1
    with pytest.raises(Interrupted, match="resume"):
        fetch(TUM, tmp_path, url_base=server.base, retries=0)
    part = tmp_path / STAGING / (TUM.filename + ".part")
    have = part.stat().st_size
    assert 0 < have < len(archives["tgz"]) and archives["tgz"].startswith(part.read_bytes())
    _nothing_half_done(tmp_path)

    done = fetch(TUM, tmp_path, url_base=server.base, retries=0)
    assert done.status == "resumed" and server.ranges(path) == [None, f"bytes={have}-"]
    assert (done.folder / "rgb.txt").is_file() and not part.exists() and not part.parent.exists()


def test_the_cli_retries_an_interrupted_transfer_in_one_call(tmp_path, server, archives):
    path = _serve(server, archives)
    server.truncate[path] = 2  # the first answer and the first resume both stop halfway
    out = CliRunner().invoke(app, ["fetch", TUM.name, "--to", str(tmp_path), "--url-base", server.base, "--quiet"])
    assert out.exit_code == 0, out.output
    assert "resumed" in out.output and (tmp_path / TUM.folder / "depth.txt").is_file()
    ranges = server.ranges(path)
    assert len(ranges) == 3 and ranges[0] is None and all(r and r.startswith("bytes=") for r in ranges[1:])


def test_a_server_that_ignores_range_restarts_the_download(tmp_path, server, archives):
    path = _serve(server, archives)
    server.truncate[path] = 1
    with pytest.raises(Interrupted):
        fetch(TUM, tmp_path, url_base=server.base, retries=0)
    server.ignore_range = True
    done = fetch(TUM, tmp_path, url_base=server.base, retries=0)
    assert done.bytes == len(archives["tgz"]) and (done.folder / "rgb.txt").is_file()
    assert server.ranges(path)[1] is not None  # it asked to resume, got a 200 and started over


def test_a_checksum_mismatch_is_refused_and_deleted(tmp_path, server, archives):
    _serve(server, archives)
    wrong = dataclasses.replace(TUM, sha256="0" * 64)
    with pytest.raises(FetchError, match="sha256 mismatch"):
        fetch(wrong, tmp_path, url_base=server.base)
    _nothing_half_done(tmp_path)
    assert not list((tmp_path / STAGING).glob("*.part"))
    right = dataclasses.replace(TUM, sha256=hashlib.sha256(archives["tgz"]).hexdigest(), size=len(archives["tgz"]))
    assert fetch(right, tmp_path, url_base=server.base).status == "downloaded"


def test_a_size_mismatch_is_refused(tmp_path, server, archives):
    _serve(server, archives)
    with pytest.raises(FetchError, match="expected"):
        fetch(dataclasses.replace(TUM, size=len(archives["tgz"]) + 1), tmp_path, url_base=server.base)
    _nothing_half_done(tmp_path)


def test_a_truncated_gzip_served_as_whole_is_refused_nothing_unpacked(tmp_path, server, archives):
    """The server announces the truncated length, so only the archive's own check can tell."""
    server.files["/" + TUM.path] = archives["tgz"][: len(archives["tgz"]) * 2 // 3]
    out = CliRunner().invoke(app, ["fetch", TUM.name, "--to", str(tmp_path), "--url-base", server.base, "--quiet"])
    assert out.exit_code != 0 and isinstance(out.exception, FetchError)
    assert "damaged or incomplete" in out.output
    _nothing_half_done(tmp_path)
    assert not list((tmp_path / STAGING).glob("*.part"))


def test_corrupted_bytes_inside_the_gzip_are_refused(tmp_path, server, archives):
    data = bytearray(archives["tgz"])
    data[len(data) // 2] ^= 0xFF
    server.files["/" + TUM.path] = bytes(data)
    with pytest.raises(FetchError, match="damaged"):
        fetch(TUM, tmp_path, url_base=server.base)
    _nothing_half_done(tmp_path)


def test_an_archive_without_the_tum_layout_is_refused(tmp_path, server, archives):
    server.files["/" + TUM.path] = archives["flat"]  # right files, but not under the expected folder
    with pytest.raises(FetchError, match="TUM-layout"):
        fetch(TUM, tmp_path, url_base=server.base)
    _nothing_half_done(tmp_path)
    server.files["/" + TUM.path] = gzip.compress(b"not a tar at all" * 100)
    with pytest.raises(FetchError):
        fetch(TUM, tmp_path, url_base=server.base)
    _nothing_half_done(tmp_path)


def test_a_sequence_already_there_is_skipped(tmp_path, server, archives):
    path = _serve(server, archives)
    fetch(TUM, tmp_path, url_base=server.base)
    out = CliRunner().invoke(app, ["fetch", TUM.folder, "--to", str(tmp_path), "--url-base", server.base])
    assert out.exit_code == 0, out.output
    assert "already present" in out.output and server.ranges(path) == [None]  # no second request


def test_a_table_name_fetches_its_sequences_and_a_missing_one_is_reported(tmp_path, server, sequence):
    names = TABLES["tum-walking"]
    for name in (names[0], names[2]):  # the second is not on this server
        ds = DATASETS[name]
        server.files["/" + ds.path] = tar_gz(sequence, tmp_path / ds.filename, top=ds.folder).read_bytes()
    to = tmp_path / "data"
    out = CliRunner().invoke(app, ["fetch", "tum-walking", "--to", str(to), "--url-base", server.base, "--quiet"])
    assert out.exit_code != 0 and isinstance(out.exception, FetchError)
    assert "HTTP 404" in out.output and "2 of 4 not fetched" in str(out.exception)
    assert sorted(p.name for p in to.iterdir()) == sorted([DATASETS[names[0]].folder, DATASETS[names[2]].folder])


def test_catalog_and_list():
    assert lookup("rgbd_dataset_freiburg3_walking_xyz") is TUM and lookup("rgbd_bonn_crowd.zip") is BONN
    assert TUM.url() == "https://cvg.cit.tum.de/rgbd/dataset/freiburg3/rgbd_dataset_freiburg3_walking_xyz.tgz"
    assert BONN.url("http://127.0.0.1:1/") == "http://127.0.0.1:1/rgbd_bonn_crowd.zip"
    assert all(n in DATASETS for names in TABLES.values() for n in names)
    out = CliRunner().invoke(app, ["fetch", "--list"])
    assert out.exit_code == 0 and "tum-fr1-xyz" in out.output and "table tum-walking" in out.output


def test_only_http_addresses_are_fetched(tmp_path):
    with pytest.raises(FetchError, match="only http"):
        fetch(TUM, tmp_path, url_base=f"file://{tmp_path}")
    assert list(tmp_path.iterdir()) == []


def test_an_archive_with_a_path_trick_is_refused_by_the_safe_extraction(tmp_path, server, sequence):
    """The layout is right, but one entry climbs out of the folder: storage's extraction refuses it."""
    import tarfile

    archive = tar_gz(sequence, tmp_path / "a.tgz", top=TUM.folder)
    with tarfile.open(archive) as tf:
        members = [(m, tf.extractfile(m).read() if m.isfile() else None) for m in tf.getmembers()]
    evil = tmp_path / "evil.tgz"
    with tarfile.open(evil, "w:gz") as tf:
        for m, data in members:
            tf.addfile(m, io.BytesIO(data) if data is not None else None)
        info = tarfile.TarInfo(f"{TUM.folder}/../../escaped.txt")
        info.size = 2
        tf.addfile(info, io.BytesIO(b"hi"))
    server.files["/" + TUM.path] = evil.read_bytes()
    to = tmp_path / "data"
    with pytest.raises(FetchError, match="cannot unpack"):
        fetch(TUM, to, url_base=server.base)
    _nothing_half_done(to)
    assert not (tmp_path / "escaped.txt").exists() and not (to / STAGING).exists()  # the .part is deleted too


def test_a_named_bench_table_runs_what_was_fetched_and_skips_the_rest(tmp_path, server, archives):
    import subprocess
    import sys

    from cli.fetch.catalog import table_sequences

    _serve(server, archives)
    fetch(TUM, tmp_path, url_base=server.base)
    present, missing = table_sequences("tum-walking", tmp_path)
    assert present == [(TUM, tmp_path / TUM.folder)] and len(missing) == 3
    bench = Path(__file__).resolve().parents[2] / "bench" / "bench_dynamic.py"
    run = subprocess.run([sys.executable, str(bench), "--table", "tum-walking", "--data", str(tmp_path),
                          "--presets", "orb-only", "--max-frames", "3"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert f"| {TUM.folder} | orb-only | 3 |" in run.stdout
    assert "skipping tum-fr3-walking-static" in run.stderr and "vtdslam fetch" in run.stderr
    empty = subprocess.run([sys.executable, str(bench), "--table", "bonn-crowd", "--data", str(tmp_path)],
                           capture_output=True, text=True, timeout=120)
    assert empty.returncode != 0 and "none of its sequences" in empty.stderr
