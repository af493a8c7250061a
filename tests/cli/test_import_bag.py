"""`vtdslam import-bag` (issue 61): a bag the test writes becomes a sequence folder; bad bags exit 2, leave nothing."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from cli.main import app
from storage.errors import InvalidInput
from tests.storage.ingest.rosbags_write import BagSpec, write_bag


def test_import_bag_json(tmp_path):
    bag = write_bag(tmp_path / "rec.bag", BagSpec(kind="ros1", gt="pose"))
    out = CliRunner().invoke(app, ["import-bag", str(bag), str(tmp_path / "seq"), "--json"])
    assert out.exit_code == 0, out.output
    report = json.loads(out.stdout)
    assert report["frames"] == 4 and report["gt_poses"] == 4 and report["camera"]["fx"] == 200.0
    assert {p.name for p in (tmp_path / "seq").iterdir()} == {
        "rgb", "depth", "rgb.txt", "depth.txt", "camera.json", "groundtruth.txt"}


def test_import_bag_named_topics_and_tf(tmp_path):
    bag = write_bag(tmp_path / "rec", BagSpec(kind="mcap", gt="tf"))
    out = CliRunner().invoke(app, ["import-bag", str(bag), str(tmp_path / "seq"), "--rgb", "/camera/rgb/image_raw",
                                   "--depth", "/camera/depth_registered/image_raw", "--gt", "/tf",
                                   "--gt-frames", "odom:base"])
    assert out.exit_code == 0, out.output
    assert "4 colour/depth pairs from a ROS2 bag" in out.stdout and "/tf  (4 poses)" in out.stdout


def test_import_bag_bad_input(tmp_path):
    bag = write_bag(tmp_path / "rec.bag", BagSpec(kind="ros1", depth=None))
    out = CliRunner().invoke(app, ["import-bag", str(bag), str(tmp_path / "seq")])
    assert isinstance(out.exception, InvalidInput) and "no depth image topic" in str(out.exception)
    out = CliRunner().invoke(app, ["import-bag", str(bag), str(tmp_path / "seq"), "--gt-frames", "odom"])
    assert isinstance(out.exception, InvalidInput) and "PARENT:CHILD" in str(out.exception)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.bag"]


def test_import_bag_exit_code(tmp_path):
    """Through `vtdslam`'s error mapping: a bad bag is exit code 2 and one line, not a trace."""
    import subprocess
    import sys

    junk = tmp_path / "x.bag"
    junk.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 64)
    proc = subprocess.run([sys.executable, "-c", "from cli.main import main; main()", "import-bag", str(junk),
                           str(tmp_path / "seq")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "not a readable ROS bag" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "seq").exists()
