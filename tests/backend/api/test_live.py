"""Live sessions through the api (TestClient, a recording queue): what is kept, and every refusal."""
from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from backend.api.live_frames import MAX_FRAME_BYTES
from backend.app import create_app
from cli.stream.client import encode_frame
from storage.ingest.sequence import validate_sequence
from storage.settings import get_settings
from tests.backend.api.data import CAMERA, write_sequence
from tests.backend.api.live_client import frame_messages, start_session


@pytest.fixture(scope="module")
def frames(tmp_path_factory: pytest.TempPathFactory) -> list[bytes]:
    return frame_messages(write_sequence(tmp_path_factory.mktemp("live") / "seq", n=6))


def _closed(ws) -> tuple[dict, int]:
    """The error message before the server closed, and the close code."""
    msg = ws.receive_json()
    with pytest.raises(WebSocketDisconnect) as info:
        ws.receive_json()
    return msg, info.value.code


def test_session_keeps_every_frame_as_a_sequence(client: TestClient, queue, frames, settings) -> None:
    s = start_session(client, CAMERA)
    assert queue.ids == [s["job_id"]]
    with client.websocket_connect(s["stream_url"]) as ws:
        ready = ws.receive_json()
        assert ready["type"] == "ready" and ready["sequence_id"] == s["sequence_id"]
        for m in frames:
            ws.send_bytes(m)
        ws.send_json({"type": "end"})
        ended = ws.receive_json()
    assert ended["type"] == "ended" and ended["frames"] == len(frames)
    seq = client.get(f"/api/v1/sequences/{s['sequence_id']}").json()
    assert seq["frames"] == len(frames)
    folder = settings.data_dir / "sequences" / s["sequence_id"]
    assert validate_sequence(folder).frames == len(frames)  # an ordinary TUM-layout sequence


def test_disconnect_mid_stream_keeps_what_was_received(client: TestClient, frames, settings) -> None:
    s = start_session(client, CAMERA)
    with client.websocket_connect(s["stream_url"]) as ws:
        ws.receive_json()
        for m in frames[:3]:
            ws.send_bytes(m)
        ws.send_json({"type": "ping"})
        assert ws.receive_json() == {"type": "pong", "frames": 3}
    # the client went away without an end message: the three frames are a sequence, the session is over
    seq = client.get(f"/api/v1/sequences/{s['sequence_id']}").json()
    assert seq["frames"] == 3
    assert validate_sequence(settings.data_dir / "sequences" / s["sequence_id"]).frames == 3


def test_a_second_client_is_refused(client: TestClient, frames) -> None:
    s = start_session(client, CAMERA)
    with client.websocket_connect(s["stream_url"]) as first:
        assert first.receive_json()["type"] == "ready"
        first.send_bytes(frames[0])
        with client.websocket_connect(s["stream_url"]) as second:
            msg, code = _closed(second)
        assert code == 4409 and msg["error"]["code"] == "conflict" and "already has a client" in msg["error"]["message"]
        first.send_bytes(frames[1])  # the first client is undisturbed
        first.send_json({"type": "end"})
        assert first.receive_json()["frames"] == 2
    with client.websocket_connect(s["stream_url"]) as late:  # after the end: the session is over
        msg, code = _closed(late)
    assert code == 4409 and "ended" in msg["error"]["message"]


def test_unknown_session_and_an_ordinary_job_are_not_streamable(client: TestClient) -> None:
    with client.websocket_connect("/api/v1/live/nosuchjob/stream") as ws:
        msg, code = _closed(ws)
    assert code == 4404 and msg["error"]["code"] == "not_found"


@pytest.mark.parametrize("bad, status, words", [
    (b"\x00\x00\x00\x05{}", 4422, "header"),
    (encode_frame(500.0, b"not an image", b"nor this"), 4422, "not a PNG or JPEG"),
    (b"\x00" * (MAX_FRAME_BYTES + 1), 4413, "at most"),
])
def test_a_bad_or_oversized_frame_is_refused_and_earlier_frames_kept(client: TestClient, frames, bad, status,
                                                                    words) -> None:
    s = start_session(client, CAMERA)
    with client.websocket_connect(s["stream_url"]) as ws:
        ws.receive_json()
        ws.send_bytes(frames[0])
        ws.send_bytes(bad)
        msg, code = _closed(ws)
    assert code == status and words in msg["error"]["message"]
    assert client.get(f"/api/v1/sequences/{s['sequence_id']}").json()["frames"] == 1


def test_frames_must_go_forward_in_time(client: TestClient, frames) -> None:
    s = start_session(client, CAMERA)
    with client.websocket_connect(s["stream_url"]) as ws:
        ws.receive_json()
        ws.send_bytes(frames[1])
        ws.send_bytes(frames[0])
        msg, code = _closed(ws)
    assert code == 4422 and "not after the previous frame" in msg["error"]["message"]


def test_token_is_required_when_set(tmp_path, queue, frames) -> None:
    settings = get_settings(data_dir=tmp_path / "data", api_token="s3cret")
    good = {"Authorization": "Bearer s3cret"}
    with TestClient(create_app(settings, enqueue=queue)) as client:
        assert client.post("/api/v1/live", json={"camera": CAMERA}).status_code == 401
        s = start_session(client, CAMERA, headers=good)
        for headers in ({}, {"Authorization": "Bearer wrong"}):
            with client.websocket_connect(s["stream_url"], headers=headers) as ws:
                msg, code = _closed(ws)
            assert code == 4401 and msg["error"]["code"] == "unauthorized"
        with client.websocket_connect(s["stream_url"], headers=good) as ws:  # refusals did not take the session
            assert ws.receive_json()["type"] == "ready"
            ws.send_bytes(frames[0])
            ws.send_json({"type": "end"})
            assert ws.receive_json()["frames"] == 1


def test_bad_session_requests_get_a_clear_4xx(client: TestClient) -> None:
    assert client.post("/api/v1/live", json={"camera": "nosuchcamera"}).status_code == 422
    assert client.post("/api/v1/live", json={"camera": CAMERA, "preset": "nosuchpreset"}).status_code == 422


def test_a_session_whose_sequence_is_deleted_ends_with_a_clear_error(client: TestClient, frames) -> None:
    s = start_session(client, CAMERA)
    with client.websocket_connect(s["stream_url"]) as ws:
        ws.receive_json()
        ws.send_bytes(frames[0])
        ws.send_json({"type": "ping"})
        assert ws.receive_json()["frames"] == 1
        assert client.delete(f"/api/v1/sequences/{s['sequence_id']}").status_code == 204
        ws.send_bytes(frames[1])
        msg, code = _closed(ws)
    assert code == 4409 and "cannot be written" in msg["error"]["message"]
    assert client.get(f"/api/v1/sequences/{s['sequence_id']}").status_code == 404


def test_a_bad_ground_truth_is_refused_and_not_kept(client: TestClient, frames, settings) -> None:
    s = start_session(client, CAMERA)
    with client.websocket_connect(s["stream_url"]) as ws:
        ws.receive_json()
        ws.send_bytes(frames[0])
        ws.send_json({"type": "groundtruth", "text": "1.0 nonsense\n"})
        msg, code = _closed(ws)
    assert code == 4422 and msg["error"]["message"].startswith("groundtruth.txt")
    assert not (settings.data_dir / "sequences" / s["sequence_id"] / "groundtruth.txt").exists()
    assert client.get(f"/api/v1/sequences/{s['sequence_id']}").json()["frames"] == 1
