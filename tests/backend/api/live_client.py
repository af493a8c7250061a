"""Helpers of the live-session tests: frames of a sequence folder as WebSocket messages, a session."""
from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from cli.stream.client import encode_frame
from cli.stream.source import tum_source


def frame_messages(folder: Path, n: int | None = None) -> list[bytes]:
    src = tum_source(folder, n)
    return [encode_frame(t, rgb.read_bytes(), depth.read_bytes()) for t, rgb, depth in src.frames]


def start_session(client: TestClient, camera: object, preset: str = "orb-only", headers: dict | None = None) -> dict:
    r = client.post("/api/v1/live", json={"camera": camera, "preset": preset}, headers=headers or {})
    assert r.status_code == 201, r.text
    return r.json()
