"""The viewer process: one viser server per opened run, so a job page opens straight onto its run.

viser serves one scene per server (clients can't say which run they want), so the hub starts a server per
run on an ephemeral port when asked, keeps at most `max_servers` (least recently opened ones with no
connected clients are stopped first) and answers a tiny JSON control API on the viewer port:

    GET /health              → {"status": "ok", "runs": [...]}
    GET /runs/{job_id}       → {"job_id": ..., "port": 40123}   (starts the run's server if needed)
"""
from __future__ import annotations

import json
import logging
import sys
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from storage.artifacts import ArtifactStore
from storage.errors import StorageError
from webui.viewer.run_data import load_run
from webui.viewer.scene import build_scene

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class HubConfig:
    host: str = "127.0.0.1"
    """Address the run servers and the control API bind to."""
    port: int = 8080
    """Control API port."""
    max_servers: int = 6
    """Run servers kept alive at once."""


class ViewerHub:
    def __init__(self, store: ArtifactStore, config: HubConfig = HubConfig()) -> None:
        self.store = store
        self.config = config
        self._servers: OrderedDict[str, object] = OrderedDict()
        self._lock = threading.Lock()

    def open_run(self, job_id: str) -> int:
        """Port of the run's viser server, started on first use."""
        import viser

        with self._lock:
            if job_id in self._servers:
                self._servers.move_to_end(job_id)
                return self._servers[job_id].get_port()
            data = load_run(self.store.job_dir(job_id))  # NotFound if the run has no trajectory
            self._evict()
            server = viser.ViserServer(host=self.config.host, port=0, label=f"VTD-SLAM run {job_id[:8]}",
                                       verbose=False)
            build_scene(server, data, f"Run {job_id[:8]}")
            self._servers[job_id] = server
            log.info("viewer for run %s on port %d", job_id, server.get_port())
            return server.get_port()

    def _evict(self) -> None:
        while len(self._servers) >= self.config.max_servers:
            idle = [k for k, s in self._servers.items() if not s.get_clients()]
            victim = idle[0] if idle else next(iter(self._servers))
            self._servers.pop(victim).stop()

    def runs(self) -> list[str]:
        with self._lock:
            return list(self._servers)

    def stop(self) -> None:
        with self._lock:
            for server in self._servers.values():
                server.stop()
            self._servers.clear()


class QuietHTTPServer(ThreadingHTTPServer):
    """A threading HTTP server whose clients may hang up early (the api times out its hub calls):
    a broken pipe is logged at debug level instead of a traceback on stderr."""

    def handle_error(self, request, client_address) -> None:  # noqa: ANN001 (socketserver's signature)
        exc = sys.exc_info()[1]
        if isinstance(exc, ConnectionError):
            log.debug("client %s hung up: %s", client_address, exc)
        else:
            log.exception("error while answering %s", client_address)


def _handler(hub: ViewerHub) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def _send(self, status: int, body: dict) -> None:
            payload = json.dumps(body).encode()
            self.send_response(status)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(payload)))
            self.send_header("Access-Control-Allow-Origin", "*")
            self.end_headers()
            self.wfile.write(payload)

        def do_GET(self) -> None:  # noqa: N802 (http.server's naming)
            parts = [p for p in self.path.split("?")[0].split("/") if p]
            if parts == ["health"]:
                return self._send(200, {"status": "ok", "runs": hub.runs()})
            if len(parts) == 2 and parts[0] == "runs":
                try:
                    return self._send(200, {"job_id": parts[1], "port": hub.open_run(parts[1])})
                except StorageError as exc:
                    return self._send(exc.http_status, {"error": exc.to_dict()})
            self._send(404, {"error": {"code": "not_found", "message": "no such path", "detail": {}}})

        def log_message(self, fmt: str, *args) -> None:
            log.debug(fmt, *args)

    return Handler


def serve_hub(hub: ViewerHub, stop: threading.Event | None = None) -> None:
    """Run the control API until `stop` is set (or forever)."""
    httpd = QuietHTTPServer((hub.config.host, hub.config.port), _handler(hub))
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    log.info("viewer hub on http://%s:%d", hub.config.host, hub.config.port)
    try:
        while stop is None or not stop.is_set():
            time.sleep(0.2)
    finally:
        httpd.shutdown()
        hub.stop()


__all__ = ["HubConfig", "QuietHTTPServer", "ViewerHub", "serve_hub"]
