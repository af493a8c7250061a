"""`vtdslam stream camera:INDEX`: an RGB-D camera through OpenCV's OpenNI2 backends, driven here by a fake capture
given to the source (no camera is attached to the test machine): its frames reach the session with their
timestamps and depth in millimetres; a camera without depth, or none at all, is a clear error saying what was
tried, before any session is made."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest
from typer.testing import CliRunner

from backend.app import create_app
from cli.main import app
from cli.stream.camera import CameraError, camera_index, open_rgbd_camera
from cli.stream_cmd import stream_camera
from storage.errors import InvalidInput
from storage.settings import get_settings
from tests.backend.api.live import serve

pytestmark = pytest.mark.usefixtures("no_vtd_env")  # tests/conftest.py

ROOT = Path(__file__).resolve().parents[2]
W, H = 160, 120
FOCAL = 130.0


class FakeCapture:
    """A cv2.VideoCapture-like camera: OpenNI retrieval flags give a uint16 depth map (mm) and a BGR image that
    change every grab; `depth` False: a camera without a depth generator."""

    def __init__(self, frames: int = 10, depth: bool = True) -> None:
        self.frames, self.depth = frames, depth
        self.grabbed = 0
        self.released = False
        self.props: dict[int, float] = {}

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        return True

    def grab(self) -> bool:
        if self.grabbed >= self.frames:
            return False
        self.grabbed += 1
        return True

    def retrieve(self, image: object = None, flag: int = 0) -> tuple[bool, np.ndarray | None]:
        k = self.grabbed
        if flag == cv2.CAP_OPENNI_DEPTH_MAP:
            return (True, np.full((H, W), 1000 + k, np.uint16)) if self.depth else (False, None)
        if flag == cv2.CAP_OPENNI_BGR_IMAGE:
            rng = np.random.default_rng(k)
            return True, rng.integers(0, 255, (H, W, 3), dtype=np.uint8)
        return False, None

    def get(self, prop: int) -> float:
        if prop == cv2.CAP_OPENNI_DEPTH_GENERATOR_PRESENT:
            return 1.0 if self.depth else 0.0
        if prop == cv2.CAP_OPENNI_DEPTH_GENERATOR_FOCAL_LENGTH:
            return FOCAL
        return 0.0

    def set(self, prop: int, value: float) -> bool:
        self.props[prop] = value
        return True

    def release(self) -> None:
        self.released = True


class Closed(FakeCapture):
    def isOpened(self) -> bool:  # noqa: N802
        return False


def _opener(make_capture, log: list[tuple[int, int]]):
    def open_capture(index: int, api: int):
        log.append((index, api))
        return make_capture(api)
    return open_capture


@pytest.fixture
def server(tmp_path):
    settings = get_settings(data_dir=tmp_path / "data")
    with serve(create_app(settings, enqueue=lambda job_id: None)) as base:
        yield base, settings


def test_camera_frames_reach_the_session_with_their_timestamps(server, capsys) -> None:
    base, settings = server
    fake = FakeCapture(frames=1 + 6)  # the first grab checks the camera
    opened: list[tuple[int, int]] = []
    stream_camera(2, base, wait=False, open_capture=_opener(lambda api: fake, opened))
    assert opened == [(2, cv2.CAP_OPENNI2)] and fake.released
    assert fake.props[cv2.CAP_OPENNI_DEPTH_GENERATOR_REGISTRATION] == 1  # depth in the colour camera's pixels
    out = capsys.readouterr().out
    assert "sent 6 frames; the server kept 6" in out
    job_id = out.split("job ", 1)[1].split()[0]
    job = httpx.get(f"{base}/api/v1/jobs/{job_id}").json()
    seq = httpx.get(f"{base}/api/v1/sequences/{job['sequence_id']}").json()
    assert seq["frames"] == 6
    assert seq["camera"]["fx"] == FOCAL and seq["camera"]["depth_scale"] == 1000.0
    folder = settings.data_dir / "sequences" / seq["id"]
    lines = [ln.split() for ln in (folder / "depth.txt").read_text().splitlines() if not ln.startswith("#")]
    stamps = [float(t) for t, _ in lines]
    assert len(stamps) == 6 and all(b > a for a, b in zip(stamps, stamps[1:]))
    for k, (_, path) in enumerate(lines):  # grabs 2..7 after the check: depth 1002.. mm, kept exactly
        depth = cv2.imread(str(folder / path), cv2.IMREAD_UNCHANGED)
        assert depth is not None and depth.dtype == np.uint16 and depth.shape == (H, W) and int(depth[0, 0]) == 1002 + k


def test_a_camera_without_depth_is_refused_before_any_session() -> None:
    fake = FakeCapture(depth=False)
    with pytest.raises(CameraError, match=r"camera 0 opened through OpenNI2 \(cv2.CAP_OPENNI2\) but has no depth"):
        open_rgbd_camera(0, _opener(lambda api: fake, []))
    assert fake.released


def test_no_camera_names_every_backend_tried() -> None:
    opened: list[tuple[int, int]] = []
    with pytest.raises(CameraError, match="no camera at index 1: tried OpenNI2") as err:
        open_rgbd_camera(1, _opener(lambda api: Closed(), opened))
    assert [api for _, api in opened] == [cv2.CAP_OPENNI2, cv2.CAP_OPENNI2_ASUS, cv2.CAP_OPENNI2_ASTRA, cv2.CAP_ANY]
    assert "CAP_OPENNI2_ASTRA" in str(err.value) and "default backend" in str(err.value)


def test_a_colour_only_camera_is_told_apart_from_no_camera() -> None:
    def make(api: int) -> FakeCapture:
        return FakeCapture() if api == cv2.CAP_ANY else Closed()

    with pytest.raises(CameraError, match="opens through OpenCV's default backend but has no depth stream"):
        open_rgbd_camera(0, _opener(make, []))


def test_the_cli_fails_with_a_message_when_no_camera_answers(tmp_path) -> None:
    """The command with the real `cv2.VideoCapture`: an index no machine has is a one-line error, exit code 2,
    before any session is asked for (the URL answers nothing)."""
    done = subprocess.run([sys.executable, "-m", "cli.main", "stream", "camera:97", "--to", "http://127.0.0.1:9",
                           "--no-wait"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert "error: no camera at index 97: tried OpenNI2 (cv2.CAP_OPENNI2)" in done.stderr
    bad = CliRunner().invoke(app, ["stream", "camera:x", "--to", "http://127.0.0.1:9"])
    assert isinstance(bad.exception, InvalidInput) and "camera:INDEX" in str(bad.exception)
    assert camera_index("camera:3") == 3 and camera_index(str(tmp_path)) is None


def test_ctrl_c_ends_the_stream_and_keeps_what_was_sent(server) -> None:
    from cli.stream.client import create_session, send_frames

    base, _ = server
    cam = open_rgbd_camera(0, _opener(lambda api: FakeCapture(frames=50), []))

    def interrupted():
        for k, frame in enumerate(cam.frames()):
            if k == 3:
                raise KeyboardInterrupt
            yield frame

    session = create_session(base, None, cam.camera_spec() or {}, "orb-only")
    report = send_frames(base, session, interrupted())
    assert report.sent == 3 and report.ended is not None
    assert report.ended["type"] == "ended" and report.ended["frames"] == 3
