"""The api process: uvicorn with the service's connection limits (``backend.http_limits``)."""

from __future__ import annotations

import uvicorn

from backend.http_limits import KEEP_ALIVE_S, MAX_HEADER_BYTES, LimitedH11Protocol


def api_config(host: str, port: int, **kwargs: object) -> uvicorn.Config:
    """The api's uvicorn config: the app factory, h11 with header size and time limits, keep-alive, WebSocket
    messages uncompressed (a live session's frames are JPEG and PNG already: deflating them again cost its client
    7 ms of CPU a frame for nothing, and the api as much to inflate them)."""
    return uvicorn.Config(
        "backend.app:create_app",
        factory=True,
        host=host,
        port=port,
        http=LimitedH11Protocol,
        h11_max_incomplete_event_size=MAX_HEADER_BYTES,
        timeout_keep_alive=KEEP_ALIVE_S,
        ws_per_message_deflate=False,
        **kwargs,  # type: ignore[arg-type]
    )


def main() -> None:
    from storage.settings import get_settings

    settings = get_settings()
    uvicorn.Server(api_config(settings.host, settings.port)).run()


if __name__ == "__main__":
    main()
