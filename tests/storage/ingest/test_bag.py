"""Issue 61: ROS 1 / ROS 2 bags imported as TUM-layout sequences, from bags the tests write."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from storage.errors import InvalidInput, PayloadTooLarge
from storage.ingest.bag import BagLimits, import_bag, is_ros1_bag
from tests.storage.ingest.rosbags_write import BagSpec, D, H, K, W, colour_frame, depth_frame, gt_pose, write_bag
from worker.slam.io.sequence import Sequence


def _bag(tmp_path: Path, spec: BagSpec, name: str = "rec") -> Path:
    return write_bag(tmp_path / (name + (".bag" if spec.kind == "ros1" else "")), spec)


def _leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if p.name.startswith("."))


@pytest.mark.parametrize(
    ("kind", "colour", "depth", "tol_m"),
    [
        ("ros1", "rgb8", "16UC1", 0.0006),
        ("ros1", "bgr8", "32FC1", 0.0002),
        ("ros1", "jpeg", "cd16", 0.0006),
        ("sqlite3", "rgb8", "32FC1", 0.0002),
        ("sqlite3", "png", "cd32", 0.004),
        ("mcap", "bgr8", "16UC1", 0.0006),
        ("mcap", "jpeg", "cd32", 0.004),
    ],
)
def test_round_trip(tmp_path, kind, colour, depth, tol_m):
    bag = _bag(tmp_path, BagSpec(kind=kind, colour=colour, depth=depth))
    out = tmp_path / "seq"
    result = import_bag(bag, out)
    assert result.bag_format == ("ros1" if kind == "ros1" else "ros2")
    assert (result.rgb_topic, result.depth_topic) == ("/camera/rgb/image_raw", "/camera/depth_registered/image_raw")
    assert result.frames == result.rgb_frames == result.depth_frames == 4
    seq = Sequence(out)  # the pipeline's own reader: camera.json, lists, association
    assert len(seq) == 4 and seq.camera_source == "camera.json"
    for i, frame in enumerate(seq):
        want = depth_frame(i)
        assert frame.depth.shape == (H, W)
        assert np.array_equal(frame.depth == 0, want == 0)  # invalid stays invalid
        assert float(np.abs(frame.depth - want).max()) <= tol_m
        if colour in ("rgb8", "bgr8", "png"):
            assert np.array_equal(frame.rgb, colour_frame(i))
        else:  # JPEG: lossy
            assert float(np.abs(frame.rgb.astype(int) - colour_frame(i)).mean()) < 12
    assert abs(seq.frames[1].timestamp - seq.frames[0].timestamp - 0.0333333) < 1e-5
    assert _leftovers(tmp_path) == []


def test_camera_json_from_camera_info(tmp_path):
    out = tmp_path / "seq"
    import_bag(_bag(tmp_path, BagSpec(kind="mcap")), out)
    cam = json.loads((out / "camera.json").read_text())
    assert (cam["fx"], cam["fy"], cam["cx"], cam["cy"]) == (K[0], K[4], K[2], K[5])
    assert cam["dist"] == pytest.approx(D) and (cam["width"], cam["height"]) == (W, H)
    assert cam["depth_scale"] == 5000.0


def test_mono_colour_and_raw_db3_file(tmp_path):
    """A single .db3 file (no metadata.yaml beside it) reads with the default type store."""
    folder = _bag(tmp_path, BagSpec(kind="sqlite3", colour="mono8"))
    (db3,) = folder.glob("*.db3")
    out = tmp_path / "seq"
    import_bag(db3, out)
    frame = Sequence(out)[0]
    assert np.array_equal(frame.rgb[..., 0], colour_frame(0)[..., 1])


@pytest.mark.parametrize(("kind", "gt"), [("ros1", "pose"), ("sqlite3", "transform"), ("mcap", "pose")])
def test_groundtruth_found(tmp_path, kind, gt):
    out = tmp_path / "seq"
    result = import_bag(_bag(tmp_path, BagSpec(kind=kind, gt=gt)), out)
    assert result.gt_topic == "/groundtruth/pose" and result.gt_poses == 4
    traj = Sequence(out).groundtruth
    assert traj is not None and len(traj) == 4
    pos, _quat = gt_pose(3)
    assert np.allclose(traj.poses[3][:3, 3], pos)


def test_groundtruth_from_tf_by_frames(tmp_path):
    bag = _bag(tmp_path, BagSpec(kind="mcap", gt="tf"))
    assert import_bag(bag, tmp_path / "none").gt_topic is None  # /tf is never taken unasked
    result = import_bag(bag, tmp_path / "first", gt="/tf")  # the first pair seen: world -> camera
    assert result.gt_poses == 4
    other = import_bag(bag, tmp_path / "odom", gt="/tf", gt_frames=("odom", "base"))
    assert other.gt_poses == 4 and "(odom -> base)" in (tmp_path / "odom" / "groundtruth.txt").read_text()
    with pytest.raises(InvalidInput, match="holds no poses map -> cam"):
        import_bag(bag, tmp_path / "bad", gt="/tf", gt_frames=("map", "cam"))
    assert not (tmp_path / "bad").exists()


def test_topics_named_by_flags(tmp_path):
    spec = BagSpec(kind="ros1", rgb_topic="/cam0/img", depth_topic="/cam0/z")  # names say nothing
    bag = _bag(tmp_path, spec)
    result = import_bag(bag, tmp_path / "auto")  # found by encoding
    assert (result.rgb_topic, result.depth_topic) == ("/cam0/img", "/cam0/z")
    result = import_bag(bag, tmp_path / "named", rgb="/cam0/img", depth="/cam0/z", info="/camera/rgb/camera_info")
    assert result.frames == 4
    with pytest.raises(InvalidInput, match="no topic '/nope'"):
        import_bag(bag, tmp_path / "bad", depth="/nope")
    with pytest.raises(InvalidInput, match="not sensor_msgs/msg/Image or"):
        import_bag(bag, tmp_path / "bad", depth="/camera/rgb/camera_info")
    assert not (tmp_path / "bad").exists()


def test_repeated_stamp_is_skipped_and_said(tmp_path):
    out = tmp_path / "seq"
    result = import_bag(_bag(tmp_path, BagSpec(kind="ros1", frames=5, repeat_stamp=2)), out)
    assert (result.rgb_frames, result.depth_frames) == (4, 5)
    assert any("1 rgb images skipped" in n for n in result.notes)
    assert len(Sequence(out)) == 4


def test_no_camera_info_writes_no_camera_json(tmp_path):
    out = tmp_path / "seq"
    result = import_bag(_bag(tmp_path, BagSpec(kind="ros1", info=False)), out)
    assert result.info_topic is None and not (out / "camera.json").exists()
    assert any("no camera.json" in n for n in result.notes)


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_missing_depth_topic(tmp_path, kind):
    bag = _bag(tmp_path, BagSpec(kind=kind, depth=None))
    with pytest.raises(InvalidInput, match="no depth image topic"):
        import_bag(bag, tmp_path / "seq")
    assert not (tmp_path / "seq").exists() and _leftovers(tmp_path) == []


def test_unsupported_colour_encoding(tmp_path):
    bag = _bag(tmp_path, BagSpec(kind="ros1", colour="yuv422"))
    with pytest.raises(InvalidInput, match="unsupported colour encoding 'yuv422'"):
        import_bag(bag, tmp_path / "seq")
    assert not (tmp_path / "seq").exists() and _leftovers(tmp_path) == []


def test_no_colour_topic(tmp_path):
    spec = BagSpec(kind="sqlite3", colour="rgb8", rgb_topic="/camera/depth/extra")  # only depth-named images
    with pytest.raises(InvalidInput, match="no colour image topic"):
        import_bag(_bag(tmp_path, spec), tmp_path / "seq")
    assert not (tmp_path / "seq").exists()


@pytest.mark.parametrize("keep", [0.3, 0.7, 0.98])
def test_truncated_ros1_bag(tmp_path, keep):
    bag = _bag(tmp_path, BagSpec(kind="ros1", frames=6))
    data = bag.read_bytes()
    bag.write_bytes(data[: int(len(data) * keep)])
    assert is_ros1_bag(bag)
    with pytest.raises(InvalidInput, match="not a readable ROS bag"):
        import_bag(bag, tmp_path / "seq")
    assert not (tmp_path / "seq").exists() and _leftovers(tmp_path) == []


def test_truncated_mcap_file(tmp_path):
    folder = _bag(tmp_path, BagSpec(kind="mcap", frames=6))
    (mcap,) = folder.glob("*.mcap")
    data = mcap.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(InvalidInput, match="not a readable ROS bag"):
        import_bag(cut, tmp_path / "seq")
    assert not (tmp_path / "seq").exists()


def test_not_a_bag(tmp_path):
    junk = tmp_path / "x.bag"
    junk.write_bytes(b"PK\x03\x04 not a bag at all")
    with pytest.raises(InvalidInput, match="not a ROS bag"):
        import_bag(junk, tmp_path / "seq")
    assert not (tmp_path / "seq").exists()


def test_ros1_bag_under_another_name(tmp_path):
    """The upload stores what it receives as a plain file: ROS 1 is told by its magic, not its suffix."""
    bag = _bag(tmp_path, BagSpec(kind="ros1"))
    renamed = bag.rename(tmp_path / "upload.bin")
    assert import_bag(renamed, tmp_path / "seq").frames == 4


def test_ros2_folder_named_like_a_ros1_bag(tmp_path):
    folder = _bag(tmp_path, BagSpec(kind="mcap"), name="rec.bag")
    assert folder.is_dir() and import_bag(folder, tmp_path / "seq").bag_format == "ros2"


def test_out_exists_is_refused(tmp_path):
    bag = _bag(tmp_path, BagSpec(kind="ros1"))
    (tmp_path / "seq").mkdir()
    with pytest.raises(InvalidInput, match="exists already"):
        import_bag(bag, tmp_path / "seq")


def test_limits(tmp_path):
    bag = _bag(tmp_path, BagSpec(kind="ros1", frames=6))
    with pytest.raises(PayloadTooLarge, match="more than 5 images"):
        import_bag(bag, tmp_path / "seq", limits=BagLimits(max_files=5))
    with pytest.raises(PayloadTooLarge, match="bytes"):
        import_bag(bag, tmp_path / "seq", limits=BagLimits(max_bytes=20_000))
    assert not (tmp_path / "seq").exists() and _leftovers(tmp_path) == []


@pytest.mark.realdata
@pytest.mark.parametrize("depth_enc", ["32FC1", "16UC1"])
def test_real_frames_round_trip_exactly(tmp_path, bonn_dev, depth_enc):
    """30 Bonn frames through a bag: the same JPEG bytes, the same depth values (Bonn's depth is mm x 5, so even
    16UC1 loses nothing), the same timestamps; so a run on either gives the same trajectory."""
    import cv2

    from tests.storage.ingest.rosbags_write import folder_to_bag

    out = tmp_path / "seq"
    result = import_bag(folder_to_bag(bonn_dev, tmp_path / "bonn.bag", 30, depth_enc), out)
    assert result.frames == 30 and result.gt_poses > 30
    ours, theirs = Sequence(out, _bonn_camera()), Sequence(bonn_dev, _bonn_camera())
    for a, b in zip(ours.frames, theirs.frames[:30]):
        assert abs(a.timestamp - b.timestamp) < 1e-6 and a.rgb_path.read_bytes() == b.rgb_path.read_bytes()
        assert np.array_equal(cv2.imread(str(a.depth_path), -1), cv2.imread(str(b.depth_path), -1))


def _bonn_camera():
    from worker.slam.camera import camera_from_preset

    return camera_from_preset("bonn")
