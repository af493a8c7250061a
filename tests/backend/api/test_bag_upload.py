"""Issue 61: POST /sequences takes a ROS bag (ROS 1 .bag; ROS 2 .mcap/.db3 file or an archive of the bag folder),
converted under the upload's limits; a bad bag is a 4xx that leaves no file and no row."""
from __future__ import annotations

import errno
import json

import pytest

from tests.backend.api.conftest import leftovers, upload
from tests.backend.api.data import zip_of
from tests.storage.ingest.rosbags_write import BagSpec, K, write_bag


def _installed(settings, body) -> set[str]:
    return {p.name for p in (settings.data_dir / "sequences" / body["id"]).iterdir()}


def test_upload_ros1_bag(client, settings, tmp_path):
    data = write_bag(tmp_path / "rec.bag", BagSpec(kind="ros1", gt="pose")).read_bytes()
    r = upload(client, data, filename="office walk.bag")
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["name"] == "office walk" and body["frames"] == 4 and body["has_groundtruth"]
    assert body["meta"]["camera_file"]["fx"] == K[0] and body["meta"]["width"] == 160
    assert _installed(settings, body) == {"rgb", "depth", "rgb.txt", "depth.txt", "camera.json", "groundtruth.txt"}
    assert not list((settings.data_dir / "staging").iterdir())


@pytest.mark.parametrize("kind", ["mcap", "sqlite3"])
def test_upload_ros2_file(client, settings, tmp_path, kind):
    folder = write_bag(tmp_path / "rec", BagSpec(kind=kind, colour="jpeg", depth="cd16"))
    (single,) = [p for p in folder.iterdir() if p.suffix in (".mcap", ".db3")]
    r = upload(client, single.read_bytes(), filename=single.name)
    assert r.status_code == 201, r.text
    assert r.json()["frames"] == 4 and r.json()["name"] == single.stem
    assert not list((settings.data_dir / "staging").iterdir())


def test_upload_zip_of_a_ros2_bag_folder(client, settings, tmp_path):
    folder = write_bag(tmp_path / "rec", BagSpec(kind="sqlite3", depth="32FC1", gt="transform"))
    r = upload(client, zip_of(folder, tmp_path / "rec.zip", top="rec").read_bytes(), filename="rec.zip")
    assert r.status_code == 201, r.text
    assert r.json()["frames"] == 4 and r.json()["has_groundtruth"]
    assert "metadata.yaml" not in _installed(settings, r.json())


@pytest.mark.parametrize(
    ("spec", "cut", "message"),
    [
        (BagSpec(kind="ros1", depth=None), None, "no depth image topic"),
        (BagSpec(kind="ros1", colour="yuv422"), None, "unsupported colour encoding"),
        (BagSpec(kind="ros1", frames=6), 0.6, "not a readable ROS bag"),
    ],
)
def test_bad_bag_leaves_nothing(client, settings, tmp_path, spec, cut, message):
    data = write_bag(tmp_path / "rec.bag", spec).read_bytes()
    if cut is not None:
        data = data[: int(len(data) * cut)]
    r = upload(client, data, filename="rec.bag")
    assert r.status_code == 422, r.text
    err = r.json()["error"]
    assert err["code"] == "invalid_input" and message in err["message"]
    assert str(settings.data_dir) not in r.text and "/tmp" not in r.text  # no server paths in the answer
    assert leftovers(settings) == [] and client.get("/api/v1/sequences").json()["total"] == 0


def test_zip_of_a_broken_ros2_folder(client, settings, tmp_path):
    folder = write_bag(tmp_path / "rec", BagSpec(kind="mcap"))
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9, relative_file_paths: [x.mcap]}")
    r = upload(client, zip_of(folder, tmp_path / "rec.zip", top="rec").read_bytes(), filename="rec.zip")
    assert r.status_code == 422, r.text
    assert "not a readable ROS bag" in r.json()["error"]["message"]
    assert str(settings.data_dir) not in r.text and "/tmp" not in r.text
    assert leftovers(settings) == []


def test_bag_past_the_file_limit_is_413(client, settings, tmp_path):
    settings.max_files = 5  # the upload limits the api passes (unpacked files), here 6 frames x 2 images
    data = write_bag(tmp_path / "rec.bag", BagSpec(kind="ros1", frames=6)).read_bytes()
    r = upload(client, data, filename="rec.bag")
    assert r.status_code == 413, r.text
    assert leftovers(settings) == [] and json.loads(r.text)["error"]["detail"] == {"max_files": 5}


def test_full_disk_while_converting_is_507(client, settings, tmp_path, monkeypatch):
    from storage.ingest.bag import writer as bag_writer

    def full(*_args: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(bag_writer, "_write", full)
    r = upload(client, write_bag(tmp_path / "rec.bag", BagSpec(kind="ros1")).read_bytes(), filename="rec.bag")
    assert r.status_code == 507, r.text
    assert r.json()["error"]["code"] == "insufficient_storage"
    assert leftovers(settings) == [] and client.get("/api/v1/sequences").json()["total"] == 0
