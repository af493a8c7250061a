import json

import cv2
import numpy as np
import pytest

from tests.worker.slam.io.helpers import write_sequence
from worker.slam.camera import Camera, camera_from_preset
from worker.slam.errors import CameraError, SequenceFormatError
from worker.slam.io.sequence import Sequence

CAM = Camera(50.0, 50.0, 32.0, 24.0, 5000.0, 64, 48)


def test_reads_associated_frames_lazily(tmp_path):
    seq = Sequence(write_sequence(tmp_path, n=4), CAM)
    assert len(seq) == 4
    f = seq[2]
    assert f.rgb.shape == (48, 64, 3) and f.rgb.dtype == np.uint8
    assert f.depth.dtype == np.float32 and np.allclose(f.depth, 1.0)  # 5000 / scale 5000
    assert f.timestamp == pytest.approx(100 + 2 / 30)
    idx, poses = seq.groundtruth_for_frames()
    assert list(idx) == [0, 1, 2, 3] and poses.shape == (4, 4, 4)


def test_rgb_is_rgb_order(tmp_path):
    root = write_sequence(tmp_path, n=1)
    bgr = np.zeros((48, 64, 3), np.uint8)
    bgr[..., 2] = 255  # red in OpenCV's BGR
    cv2.imwrite(str(next((root / "rgb").iterdir())), bgr)
    assert Sequence(root, CAM)[0].rgb[0, 0].tolist() == [255, 0, 0]


def test_missing_list_names_the_file(tmp_path):
    root = write_sequence(tmp_path)
    (root / "depth.txt").unlink()
    with pytest.raises(SequenceFormatError, match="depth.txt"):
        Sequence(root, CAM)


def test_bad_line_names_file_and_line(tmp_path):
    root = write_sequence(tmp_path)
    (root / "rgb.txt").write_text("# c\n100.0 rgb/a.png\nnot-a-time rgb/b.png\n")
    with pytest.raises(SequenceFormatError, match=r"rgb.txt:3"):
        Sequence(root, CAM)


def test_escaping_path_rejected(tmp_path):
    root = write_sequence(tmp_path)
    (root / "rgb.txt").write_text("100.0 ../../etc/passwd\n")
    with pytest.raises(SequenceFormatError, match="inside the sequence"):
        Sequence(root, CAM)


def test_eight_bit_depth_rejected(tmp_path):
    seq = Sequence(write_sequence(tmp_path, depth_dtype=np.uint8), CAM)
    with pytest.raises(SequenceFormatError, match="16-bit"):
        seq[0]


def test_mismatched_sizes_rejected(tmp_path):
    root = write_sequence(tmp_path, n=1)
    cv2.imwrite(str(next((root / "depth").iterdir())), np.ones((24, 32), np.uint16))
    with pytest.raises(SequenceFormatError, match="sizes differ"):
        Sequence(root, CAM)[0]


def test_corrupt_image_rejected(tmp_path):
    root = write_sequence(tmp_path, n=1)
    next((root / "rgb").iterdir()).write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    with pytest.raises(SequenceFormatError, match="decodable"):
        Sequence(root, CAM)[0]


def test_huge_png_header_rejected_before_decoding(tmp_path):
    root = write_sequence(tmp_path, n=1)
    path = next((root / "rgb").iterdir())
    data = bytearray(path.read_bytes())
    data[16:24] = (30000).to_bytes(4, "big") * 2  # IHDR width, height
    path.write_bytes(bytes(data))
    with pytest.raises(SequenceFormatError, match="too large"):
        Sequence(root, CAM)[0]


def test_no_pairs_within_tolerance(tmp_path):
    root = write_sequence(tmp_path)
    (root / "depth.txt").write_text("500.0 depth/x.png\n")
    with pytest.raises(SequenceFormatError, match="no rgb/depth pairs"):
        Sequence(root, CAM)


def test_camera_file_in_folder_wins(tmp_path):
    root = write_sequence(tmp_path)
    (root / "camera.json").write_text(json.dumps({"fx": 60, "fy": 61, "cx": 30, "cy": 20, "depth_scale": 1000,
                                                  "width": 64, "height": 48}))
    seq = Sequence(root, camera_from_preset("tum3"))
    assert seq.camera.fx == 60 and seq.camera_source == "camera.json"
    assert np.allclose(seq[0].depth, 5.0)  # 5000 / 1000


def test_no_camera_at_all(tmp_path):
    with pytest.raises(CameraError):
        Sequence(write_sequence(tmp_path), None)


def test_camera_rescaled_to_image_size(tmp_path):
    seq = Sequence(write_sequence(tmp_path, size=(320, 240)), camera_from_preset("tum3"))
    seq[0]
    assert seq.camera.width == 320 and seq.camera.fx == pytest.approx(535.4 / 2)


def test_reads_7scenes(redkitchen):
    seq = Sequence(redkitchen, camera_from_preset("7scenes"))
    assert len(seq) == 1000
    f = seq[500]
    assert f.rgb.shape == (480, 640, 3) and 0.5 < float(np.median(f.depth[f.depth > 0])) < 4
    idx, _ = seq.groundtruth_for_frames()
    assert len(idx) == 1000
