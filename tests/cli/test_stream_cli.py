"""`vtdslam stream` against a real api server (uvicorn in a thread; no worker: the session's frames are kept
whatever runs them): a TUM folder and a ROS bag become the session's sequence, with camera and ground truth."""
from __future__ import annotations

import httpx
import pytest
from typer.testing import CliRunner

from backend.app import create_app
from cli.main import app
from storage.errors import InvalidInput
from storage.settings import get_settings
from tests.backend.api.data import write_sequence
from tests.backend.api.live import serve
from tests.storage.ingest.rosbags_write import BagSpec, write_bag

pytestmark = pytest.mark.usefixtures("no_vtd_env")  # tests/conftest.py


@pytest.fixture
def server(tmp_path):
    queued: list[str] = []
    settings = get_settings(data_dir=tmp_path / "data", api_token="tok")
    with serve(create_app(settings, enqueue=queued.append)) as base:
        yield base, settings


def _sequence(base: str, job_id: str) -> dict:
    job = httpx.get(f"{base}/api/v1/jobs/{job_id}").json()
    return httpx.get(f"{base}/api/v1/sequences/{job['sequence_id']}").json()


def _job_id(output: str) -> str:
    return output.split("job ", 1)[1].split()[0]


def test_stream_a_tum_folder(server, tmp_path) -> None:
    base, _ = server
    folder = write_sequence(tmp_path / "seq", n=8)
    out = CliRunner().invoke(app, ["stream", str(folder), "--to", base, "--token", "tok", "--rate", "200",
                                   "--no-wait", "--preset", "orb-only"])
    assert out.exit_code == 0, out.output
    assert "sent 8 frames; the server kept 8 (client ended the stream)" in out.stdout
    seq = _sequence(base, _job_id(out.stdout))
    assert seq["frames"] == 8 and seq["has_groundtruth"]


def test_stream_a_ros_bag(server, tmp_path) -> None:
    base, _ = server
    bag = write_bag(tmp_path / "rec.bag", BagSpec(kind="ros1", gt="pose", frames=5))
    out = CliRunner().invoke(app, ["stream", str(bag), "--to", base, "--token", "tok", "--rate", "200", "--no-wait"])
    assert out.exit_code == 0, out.output
    seq = _sequence(base, _job_id(out.stdout))
    assert seq["frames"] == 5 and seq["has_groundtruth"]
    assert seq["camera"]["fx"] == 200.0  # the bag's CameraInfo is the session's camera


def test_stream_refusals_are_one_line_errors(server, tmp_path) -> None:
    base, _ = server
    folder = write_sequence(tmp_path / "seq", n=2)
    out = CliRunner().invoke(app, ["stream", str(folder), "--to", base, "--token", "wrong", "--no-wait"])
    assert isinstance(out.exception, InvalidInput) and "401" in str(out.exception)
    (folder / "camera.json").unlink()
    out = CliRunner().invoke(app, ["stream", str(folder), "--to", base, "--token", "tok", "--no-wait"])
    assert isinstance(out.exception, InvalidInput) and "--camera" in str(out.exception)
