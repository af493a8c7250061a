"""Sequence upload (streamed, validated, atomic), import, list, get, thumbnail, delete — and every way
an upload can be wrong: each a clear 4xx that leaves no file and no row behind."""
from __future__ import annotations

import io
import json
import tarfile
import warnings
import zipfile
from pathlib import Path

import pytest

from formats.tum_lists import MAX_LIST_LINES
from storage.db import make_engine, make_session_factory
from storage.repositories import sequences
from tests.backend.api.conftest import leftovers, upload
from tests.backend.api.data import tar_gz, tar_with, write_sequence, zip_of


def _count(settings) -> int:
    engine = make_engine(settings)
    try:
        with make_session_factory(engine)() as s:
            return sequences.count(s)
    finally:
        engine.dispose()


def test_upload_tgz_with_one_top_folder(client, settings, seq_tgz):
    r = upload(client, seq_tgz, filename="rgbd_dataset_test.tgz")
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["name"] == "rgbd_dataset_test" and body["frames"] == 6 and body["has_groundtruth"]
    assert body["camera"] == {"preset": "tum1"} and body["meta"]["width"] == 160
    assert body["duration_s"] == pytest.approx(5 / 30, abs=1e-4)
    seq_dir = settings.data_dir / "sequences" / body["id"]
    assert (seq_dir / "rgb.txt").is_file() and (seq_dir / "depth" ).is_dir()
    assert not list((settings.data_dir / "staging").iterdir())
    assert client.get(f"/api/v1/sequences/{body['id']}").json() == body
    thumb = client.get(body["thumbnail_url"])
    assert thumb.status_code == 200 and thumb.headers["content-type"] == "image/png"
    assert thumb.content[:4] == b"\x89PNG"


def test_upload_zip_of_the_folder_contents_with_intrinsics(client, seq_folder, tmp_path):
    data = zip_of(seq_folder, tmp_path / "s.zip", top=None).read_bytes()
    cam = json.dumps({"fx": 100, "fy": 100, "cx": 80, "cy": 60, "width": 160, "height": 120})
    r = upload(client, data, filename="bonn.zip", camera=cam, name="my run")
    assert r.status_code == 201, r.text
    assert r.json()["name"] == "my run" and r.json()["camera"]["fx"] == 100.0


def test_list_paging_and_delete(client, settings, seq_tgz, queue):
    ids = [upload(client, seq_tgz, allow_duplicate=True).json()["id"] for _ in range(3)]
    page = client.get("/api/v1/sequences?limit=2").json()
    assert page["total"] == 3 and len(page["items"]) == 2 and page["items"][0]["id"] == ids[-1]
    assert client.get("/api/v1/sequences?limit=2&offset=2").json()["items"][0]["id"] == ids[0]
    job = client.post("/api/v1/jobs", json={"sequence_id": ids[0], "preset": "orb-only"}).json()
    (settings.data_dir / "artifacts" / job["id"]).mkdir(parents=True)
    (settings.data_dir / "artifacts" / job["id"] / "map.ply").write_text("ply")
    assert client.delete(f"/api/v1/sequences/{ids[0]}").status_code == 204
    assert client.get(f"/api/v1/sequences/{ids[0]}").status_code == 404
    assert client.get(f"/api/v1/jobs/{job['id']}").status_code == 404
    assert not (settings.data_dir / "sequences" / ids[0]).exists()
    assert not (settings.data_dir / "artifacts" / job["id"]).exists()
    r = client.delete(f"/api/v1/sequences/{ids[0]}")
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"


@pytest.mark.parametrize("query", ["limit=0", "limit=5000", "offset=-1", "limit=x"])
def test_bad_paging_is_422(client, query):
    r = client.get(f"/api/v1/sequences?{query}")
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_input"


def test_get_unknown_and_thumbnail_unknown(client):
    assert client.get("/api/v1/sequences/nope").status_code == 404
    assert client.get("/api/v1/sequences/nope/thumbnail").status_code == 404


# ---- rejected uploads: a clear 4xx, nothing on disk, nothing in the database ---------------------------

def _tar_entry(name: str, kind=tarfile.REGTYPE, **kw) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.type = kind
    for k, v in kw.items():
        setattr(info, k, v)
    return info


def _zip_bytes(entries: dict[str, bytes] | list[tuple[str, bytes]], *, mode: int | None = None) -> bytes:
    buf = io.BytesIO()
    items = entries.items() if isinstance(entries, dict) else entries
    with warnings.catch_warnings(), zipfile.ZipFile(buf, "w") as zf:
        warnings.simplefilter("ignore")  # duplicate names are what one test wants
        for name, data in items:
            info = zipfile.ZipInfo(name)
            if mode is not None:
                info.external_attr = mode << 16
            zf.writestr(info, data)
    return buf.getvalue()


def _broken_folder(tmp_path: Path, breaker) -> bytes:
    folder = write_sequence(tmp_path / "broken", n=4)
    breaker(folder)
    return tar_gz(folder, tmp_path / "broken.tgz").read_bytes()


def _corrupt_png(folder: Path) -> None:
    p = sorted((folder / "rgb").iterdir())[0]
    data = bytearray(p.read_bytes())
    data[60] ^= 0xFF
    p.write_bytes(bytes(data))


def _depth_8bit(folder: Path) -> None:
    import cv2
    import numpy as np

    for p in (folder / "depth").iterdir():
        cv2.imwrite(str(p), np.full((120, 160), 50, np.uint8))


def _size_mismatch(folder: Path) -> None:
    import cv2
    import numpy as np

    for p in (folder / "depth").iterdir():
        cv2.imwrite(str(p), np.full((60, 80), 5000, np.uint16))


BAD_FOLDERS = {
    "no rgb.txt": (lambda f: (f / "rgb.txt").unlink(), "no TUM-layout sequence"),
    "no depth.txt": (lambda f: (f / "depth.txt").unlink(), "depth.txt: required file is missing"),
    "missing image": (lambda f: sorted((f / "rgb").iterdir())[1].unlink(), "is missing"),
    "bad timestamp": (lambda f: (f / "rgb.txt").write_text("abc rgb/x.png\n"), "rgb.txt:1: timestamp"),
    "escaping path": (lambda f: (f / "rgb.txt").write_text("1.0 ../../etc/passwd\n"), "must be relative"),
    "no pairs": (lambda f: (f / "depth.txt").write_text(
        "\n".join(f"{500 + i} {p.relative_to(f)}" for i, p in enumerate(sorted((f / "depth").iterdir())))),
        "no rgb/depth pairs"),
    "bad groundtruth": (lambda f: (f / "groundtruth.txt").write_text("1 2 3\n"), "groundtruth.txt:1"),
    "zero quaternion": (lambda f: (f / "groundtruth.txt").write_text("1 2 3 4 0 0 0 0\n"), "not unit length"),
    "too many lines": (lambda f: (f / "rgb.txt").write_text("# x\n" * (MAX_LIST_LINES + 1)), "at most 100000"),
    "bad camera.json": (lambda f: (f / "camera.json").write_text('{"fx": 0, "fy": 1, "cx": 1, "cy": 1}'),
                        "camera.json: camera fx must be positive"),
    "corrupt png": (_corrupt_png, "corrupt"),
    "8-bit depth": (_depth_8bit, "16-bit single-channel PNG"),
    "size mismatch": (_size_mismatch, "depth is 80x60 but colour is 160x120"),
    "not an image": (lambda f: sorted((f / "rgb").iterdir())[0].write_bytes(b"hello"), "not a PNG or JPEG"),
}


@pytest.mark.parametrize("case", sorted(BAD_FOLDERS))
def test_invalid_sequences_are_rejected_cleanly(client, settings, tmp_path, case):
    breaker, message = BAD_FOLDERS[case]
    r = upload(client, _broken_folder(tmp_path, breaker))
    assert r.status_code == 422, r.text
    assert r.json()["error"]["code"] == "invalid_input"
    assert message in r.json()["error"]["message"]
    assert leftovers(settings) == [] and _count(settings) == 0


def _bad_archives() -> dict[str, tuple[bytes, int, str]]:
    reg = b"1.0 rgb/a.png\n"
    return {
        "not an archive": (b"just some text, not an archive" * 10, 422, "not a .zip or .tar.gz"),
        "truncated tgz": (tar_with([_tar_entry("seq/rgb.txt")], {"seq/rgb.txt": reg})[:40], 422, "not a readable"),
        "dot-dot": (tar_with([_tar_entry("seq/../../evil.txt")], {"seq/../../evil.txt": b"x"}), 422, "'..'"),
        "absolute": (tar_with([_tar_entry("/tmp/evil.txt")], {"/tmp/evil.txt": b"x"}), 422, "absolute path"),
        "symlink": (tar_with([_tar_entry("seq/link", tarfile.SYMTYPE, linkname="/etc/passwd")]), 422, "links"),
        "hardlink": (tar_with([_tar_entry("seq/hl", tarfile.LNKTYPE, linkname="seq/rgb.txt")]), 422, "links"),
        "device": (tar_with([_tar_entry("seq/dev", tarfile.CHRTYPE, devmajor=1, devminor=3)]), 422, "devices"),
        "fifo": (tar_with([_tar_entry("seq/fifo", tarfile.FIFOTYPE)]), 422, "links and devices"),
        "non-utf8 name": (tar_with([_tar_entry("seq/\udcff.png")], {"seq/\udcff.png": b"x"}), 422, "not UTF-8"),
        "non-utf8 zip name": (_zip_bytes({"seq/\u00e9.png": b"x"}).replace("\u00e9".encode(), b"\xe9\x20"), 422,
                              "not UTF-8"),
        "zip symlink": (_zip_bytes({"seq/link": b"/etc/passwd"}, mode=0o120777), 422, "links"),
        "zip slip": (_zip_bytes({"../evil.txt": b"x"}), 422, "'..'"),
        "backslash": (_zip_bytes({"seq\\..\\evil.txt": b"x"}), 422, "backslash"),
        "empty zip": (_zip_bytes({}), 422, "empty"),
        "duplicate": (_zip_bytes([("seq/rgb.txt", reg), ("seq/rgb.txt", b"2.0 rgb/b.png\n")]), 422, "duplicate"),
        "no sequence": (_zip_bytes({"a.txt": b"1", "b/c.txt": b"2"}), 422, "no TUM-layout sequence"),
    }


@pytest.mark.parametrize("case", sorted(_bad_archives()))
def test_unsafe_or_broken_archives_are_rejected_cleanly(client, settings, case):
    data, status, message = _bad_archives()[case]
    r = upload(client, data)
    assert r.status_code == status, r.text
    assert message in r.json()["error"]["message"]
    assert leftovers(settings) == [] and _count(settings) == 0
    assert not (settings.data_dir.parent / "evil.txt").exists() and not Path("/tmp/evil.txt").exists()


@pytest.mark.parametrize("kind", ["zip", "tgz"])
def test_compression_bomb(tmp_path, kind):
    """Ratio 5: archives may unpack to 5 x max(their size, 1 MiB); 20 MB of zeros in ~20 kB is refused."""
    from fastapi.testclient import TestClient

    from backend.app import create_app
    from storage.settings import get_settings

    buf = io.BytesIO()
    if kind == "zip":
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("seq/rgb.txt", b"0" * 20_000_000)
    else:
        buf.write(tar_with([_tar_entry("seq/rgb.txt")], {"seq/rgb.txt": b"0" * 20_000_000}))
    s = get_settings(data_dir=tmp_path / "d", max_ratio=5)
    with TestClient(create_app(s, enqueue=lambda _id: None)) as c:
        r = upload(c, buf.getvalue())
    assert r.status_code == 413 and "compression bomb" in r.json()["error"]["message"]
    assert leftovers(s) == [] and _count(s) == 0


def test_too_many_files_and_too_large_uploads(tmp_path, seq_tgz):
    from fastapi.testclient import TestClient

    from backend.app import create_app
    from storage.settings import get_settings

    s = get_settings(data_dir=tmp_path / "d", max_files=5, max_upload_bytes=len(seq_tgz) + 10)
    with TestClient(create_app(s, enqueue=lambda _id: None)) as c:
        r = upload(c, seq_tgz)
        assert r.status_code == 413 and "more than 5 entries" in r.json()["error"]["message"]
        r = upload(c, seq_tgz + b"\0" * 100)
        assert r.status_code == 413 and r.json()["error"]["code"] == "payload_too_large"
        assert leftovers(s) == [] and _count(s) == 0


@pytest.mark.parametrize("form, files, message", [
    ({}, True, "'camera' field"),
    ({"camera": "tum9"}, True, "unknown camera preset"),
    ({"camera": "{bad json"}, True, "not valid JSON"),
    ({"camera": "tum1"}, False, "'file' file part"),
])
def test_bad_forms(client, settings, seq_tgz, form, files, message):
    kw = {"files": {"file": ("s.tgz", seq_tgz)}} if files else {"files": {"other": ("x", b"x")}}
    r = client.post("/api/v1/sequences", data=form, **kw)
    assert r.status_code == 422, r.text
    assert message in r.json()["error"]["message"]
    assert leftovers(settings) == [] and _count(settings) == 0


def test_camera_of_another_aspect_ratio_is_422(client, settings, tmp_path):
    folder = write_sequence(tmp_path / "nocam", n=3, camera_json=False)
    data = tar_gz(folder, tmp_path / "nocam.tgz").read_bytes()
    cam = '{"fx": 100, "fy": 100, "cx": 50, "cy": 50, "width": 100, "height": 100}'
    r = upload(client, data, camera=cam)
    assert r.status_code == 422 and "aspect ratio" in r.json()["error"]["message"]
    assert upload(client, data, camera="tum3").status_code == 201  # 640x480 presets scale to 160x120
    assert leftovers(settings) and _count(settings) == 1


def test_not_multipart_is_422(client, settings):
    r = client.post("/api/v1/sequences", json={"file": "x"})
    assert r.status_code == 422 and "multipart/form-data" in r.json()["error"]["message"]
    r = client.post("/api/v1/sequences", content=b"--xyz\r\ngarbage", headers={
        "content-type": "multipart/form-data; boundary=xyz"})
    assert r.status_code == 422
    assert leftovers(settings) == []


# ---- registering a server folder ----------------------------------------------------------------------

def test_import_a_folder_under_the_import_root(client, settings):
    folder = write_sequence(settings.import_root / "tum" / "seq_a", n=4)
    r = client.post("/api/v1/sequences/import", json={"path": "tum/seq_a", "camera": "tum1"})
    assert r.status_code == 201, r.text
    seq = r.json()
    assert seq["name"] == "seq_a" and seq["frames"] == 4 and seq["meta"]["source"] == "import"
    assert client.delete(f"/api/v1/sequences/{seq['id']}").status_code == 204
    assert (folder / "rgb.txt").is_file()  # registered folders are never deleted


@pytest.mark.parametrize("path, status", [("../outside", 422), ("/etc", 422), ("missing", 404)])
def test_import_outside_the_root_or_missing(client, settings, path, status):
    settings.import_root.mkdir(parents=True, exist_ok=True)
    write_sequence(settings.import_root.parent / "outside", n=2)
    r = client.post("/api/v1/sequences/import", json={"path": path, "camera": "tum1"})
    assert r.status_code == status, r.text
    assert _count(settings) == 0


def test_import_disabled_without_a_root(tmp_path):
    from fastapi.testclient import TestClient

    from backend.app import create_app
    from storage.settings import get_settings

    with TestClient(create_app(get_settings(data_dir=tmp_path / "d"), enqueue=lambda _id: None)) as c:
        r = c.post("/api/v1/sequences/import", json={"path": "x", "camera": "tum1"})
        assert r.status_code == 422 and "disabled" in r.json()["error"]["message"]


def test_stale_upload_staging_is_swept_at_startup(settings, queue):
    import os
    import time

    from fastapi.testclient import TestClient

    from backend.app import create_app

    staging = settings.data_dir / "staging"
    old, fresh = staging / "upload-old", staging / "upload-fresh"
    for d in (old, fresh):
        (d / "unpacked").mkdir(parents=True)
        (d / "archive").write_bytes(b"x")
    week_ago = time.time() - 7 * 86400
    for p in (old, old / "unpacked", old / "archive"):
        os.utime(p, (week_ago, week_ago))
    with TestClient(create_app(settings, enqueue=queue)):
        pass
    assert not old.exists() and fresh.exists()


@pytest.mark.realdata
def test_real_7scenes_sequence_uploads_as_a_bonn_style_zip(client, settings, redkitchen, tmp_path):
    """1000 real frames (JPEG colour, 16-bit PNG depth, ground truth) in a stored zip with one top folder."""
    archive = zip_of(redkitchen, tmp_path / "redkitchen.zip", top="redkitchen", stored=True)
    with open(archive, "rb") as fh:
        r = client.post("/api/v1/sequences", files={"file": ("redkitchen.zip", fh)}, data={"camera": "7scenes"})
    assert r.status_code == 201, r.text
    seq = r.json()
    assert (seq["name"], seq["frames"], seq["has_groundtruth"]) == ("redkitchen", 1000, True)
    assert seq["duration_s"] == pytest.approx(33.3, abs=0.01) and seq["meta"]["width"] == 640
    assert client.get(seq["thumbnail_url"]).headers["content-type"] == "image/jpeg"
