"""Live frames travel uncompressed: JPEG and PNG gain nothing from the WebSocket's per-message deflate, which cost
the client (and the api, inflating) 7 ms of CPU a 210 kB Bonn frame (bench/bench_live.py)."""
from __future__ import annotations

import json
import threading

from cli.api_server import api_config
from cli.stream.client import send_frames


def test_the_client_offers_no_deflate_and_its_frames_arrive_whole() -> None:
    from websockets.sync.server import serve

    extensions: list[str | None] = []
    received: list[bytes] = []

    def handler(ws) -> None:  # noqa: ANN001 - a websockets connection
        extensions.append(ws.request.headers.get("Sec-WebSocket-Extensions"))
        ws.send(json.dumps({"type": "ready"}))
        for message in ws:
            if isinstance(message, bytes):
                received.append(message)
            elif json.loads(message)["type"] == "end":
                ws.send(json.dumps({"type": "ended", "frames": len(received)}))
                return

    with serve(handler, "127.0.0.1", 0) as server:
        threading.Thread(target=server.serve_forever, daemon=True).start()
        port = server.socket.getsockname()[1]
        session = {"job_id": "j", "sequence_id": "s", "stream_url": "/stream"}
        frames = [(1.0 + k, b"\xff\xd8colour" * 100, b"\x89PNGdepth" * 100) for k in range(3)]
        report = send_frames(f"http://127.0.0.1:{port}", session, frames)
        server.shutdown()
    assert extensions == [None]  # websockets offers permessage-deflate unless told not to
    assert report.sent == 3 and report.ended == {"type": "ended", "frames": 3}
    assert len(received) == 3 and all(b"colour" in m and m.endswith(b"\x89PNGdepth") for m in received)


def test_the_api_accepts_no_deflate() -> None:
    assert api_config("127.0.0.1", 0).ws_per_message_deflate is False
