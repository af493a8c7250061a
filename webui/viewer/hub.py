"""The viewer process: one viser server per opened run, so a job page opens straight onto its run.

viser serves one scene per server (clients can't say which run they want), so the hub starts a server per
run on an ephemeral port when asked, keeps at most `max_servers` (least recently opened ones with no
connected clients are stopped first) and answers a tiny JSON control API on the viewer port, for the api
only (browsers reach a run's scene through the api's same-origin proxy, ``/viewer/{job_id}/``):

    GET /health              → {"status": "ok"}                    (no run ids: they are not public)
    GET /runs/{job_id}       → {"job_id": ..., "host": "127.0.0.1", "port": 40123}   (starts the server)

When a key is set (the api has a token), ``/runs`` needs it in the ``X-VTD-Hub-Key`` header and the run
servers bind loopback: viser has no auth of its own, so they are then reachable only through the api.
"""
from __future__ import annotations

import hmac
import json
import logging
import sys
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import TYPE_CHECKING, Any

from storage.artifacts import ArtifactStore
from storage.errors import StorageError, Unreadable
from webui.viewer.live_scene import PARTIAL, LiveScene, partial_state
from webui.viewer.run_data import load_run
from webui.viewer.scene import build_scene

if TYPE_CHECKING:
    import viser

log = logging.getLogger(__name__)

KEY_HEADER = "X-VTD-Hub-Key"
"""The header carrying the hub key (``Settings.viewer_hub_key``) from the api to the hub."""
_WILDCARDS = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}


def reachable_host(bind_host: str) -> str:
    """The address a local client dials for a server bound to ``bind_host`` (a wildcard means loopback)."""
    return _WILDCARDS.get(bind_host, bind_host)


@dataclass(frozen=True)
class HubConfig:
    host: str = "127.0.0.1"
    """Address the control API and (without a key) the run servers bind to."""
    port: int = 8080
    """Control API port."""
    max_servers: int = 6
    """Run servers kept alive at once."""
    key: str | None = field(default=None, repr=False)
    """When set: the secret ``/runs`` requires, and the run servers bind loopback."""
    client_timeout_s: float = 10.0
    """A control client silent this long is dropped (a slow client never holds a thread)."""
    refresh_s: float = 1.0
    """A running job's scene is redrawn from its partial results this often (``live_scene``)."""

    @property
    def run_host(self) -> str:
        """Where the per-run viser servers bind."""
        return "127.0.0.1" if self.key else self.host


@dataclass(frozen=True)
class RunServer:
    """Where one run's viser server answers (HTTP for its page, WebSocket for its scene)."""

    host: str
    port: int


class ViewerHub:
    def __init__(self, store: ArtifactStore, config: HubConfig = HubConfig()) -> None:
        self.store = store
        self.config = config
        self._servers: OrderedDict[str, viser.ViserServer] = OrderedDict()
        self._live: dict[str, LiveScene] = {}
        self._lock = threading.Lock()
        self._refresher: threading.Thread | None = None
        self._stopped = threading.Event()

    def open_run(self, job_id: str) -> RunServer:
        """The run's viser server, started on first use."""
        import viser

        with self._lock:
            if job_id in self._servers:
                self._servers.move_to_end(job_id)
                return self._address(self._servers[job_id])
            run_dir = self.store.job_dir(job_id)
            try:
                running = partial_state(run_dir) == PARTIAL  # a running job's snapshots: a scene that grows
                data = None if running else load_run(run_dir)  # NotFound if the run has no trajectory
            except OSError as exc:  # files of another user on shared storage, an I/O error
                raise Unreadable(
                    f"the 3D viewer cannot read run {job_id}'s files ({exc.strerror or exc}); "
                    "check the data dir's permissions", {"errno": exc.errno},
                ) from exc
            self._evict()
            server = viser.ViserServer(host=self.config.run_host, port=0, label=f"VTD-SLAM run {job_id[:8]}",
                                       verbose=False)
            if data is not None:
                build_scene(server, data, f"Run {job_id[:8]}")
            else:
                live = LiveScene(server, run_dir, f"Run {job_id[:8]}")
                if live.refresh():
                    self._live[job_id] = live
                    self._start_refresher()
            self._servers[job_id] = server
            log.info("viewer for run %s on %s:%d", job_id, self.config.run_host, server.get_port())
            return self._address(server)

    def _start_refresher(self) -> None:
        if self._refresher is None:
            self._refresher = threading.Thread(target=self._refresh_loop, name="viewer-refresh", daemon=True)
            self._refresher.start()

    def _refresh_loop(self) -> None:
        """Redraw the running jobs' scenes; a scene whose run is final is left as the finished run's."""
        while not self._stopped.wait(self.config.refresh_s):
            with self._lock:
                for job_id, live in list(self._live.items()):
                    try:
                        going = live.refresh()
                    except Exception:  # one broken run never stops the others' updates
                        log.exception("run %s: the live scene could not be redrawn", job_id)
                        going = False
                    if not going:
                        del self._live[job_id]

    def _address(self, server: viser.ViserServer) -> RunServer:
        return RunServer(reachable_host(self.config.run_host), server.get_port())

    def _evict(self) -> None:
        while len(self._servers) >= self.config.max_servers:
            idle = [k for k, s in self._servers.items() if not s.get_clients()]
            victim = idle[0] if idle else next(iter(self._servers))
            self._servers.pop(victim).stop()
            self._live.pop(victim, None)

    def runs(self) -> list[str]:
        with self._lock:
            return list(self._servers)

    def stop(self) -> None:
        self._stopped.set()
        with self._lock:
            self._live.clear()
            for server in self._servers.values():
                server.stop()
            self._servers.clear()


class QuietHTTPServer(ThreadingHTTPServer):
    """A threading HTTP server whose clients may hang up early (the api times out its hub calls):
    a broken pipe is logged at debug level instead of a traceback on stderr."""

    daemon_threads = True

    def handle_error(self, request: Any, client_address: Any) -> None:  # socketserver's signature
        exc = sys.exc_info()[1]
        if isinstance(exc, (ConnectionError, TimeoutError)):
            log.debug("client %s hung up or timed out: %s", client_address, exc)
        else:
            log.exception("error while answering %s", client_address)


def _handler(hub: ViewerHub) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        timeout = hub.config.client_timeout_s  # socket timeout for every read: slow clients are dropped

        def _send(self, status: int, body: dict[str, Any]) -> None:
            payload = json.dumps(body).encode()
            self.send_response(status)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(payload)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()  # no CORS header: browsers never call the hub, the api does
            self.wfile.write(payload)

        def _error(self, status: int, code: str, message: str) -> None:
            self._send(status, {"error": {"code": code, "message": message, "detail": {}}})

        def _authorised(self) -> bool:
            key = hub.config.key
            if not key:
                return True
            given = self.headers.get(KEY_HEADER) or ""
            return hmac.compare_digest(given.encode(), key.encode())

        def do_GET(self) -> None:  # noqa: N802 (http.server's naming)
            parts = [p for p in self.path.split("?")[0].split("/") if p]
            if parts == ["health"]:
                return self._send(200, {"status": "ok"})
            if len(parts) == 2 and parts[0] == "runs":
                if not self._authorised():
                    return self._error(403, "forbidden", "the viewer hub answers the api only")
                try:
                    run = hub.open_run(parts[1])
                except StorageError as exc:
                    if exc.http_status >= 500:
                        log.error("run %s: %s", parts[1], exc.message, exc_info=exc.__cause__)
                    return self._send(exc.http_status, {"error": exc.to_dict()})
                except Exception:  # answered, so the api says "failed", not "the viewer is not running"
                    log.exception("could not open run %s", parts[1])
                    return self._error(500, "viewer_error", "the 3D viewer failed to open the run; see its log")
                return self._send(200, {"job_id": parts[1], "host": run.host, "port": run.port})
            self._error(404, "not_found", "no such path")

        def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (http.server's naming)
            log.debug(format, *args)

    return Handler


def serve_hub(hub: ViewerHub, stop: threading.Event | None = None) -> None:
    """Run the control API until `stop` is set (or forever)."""
    httpd = QuietHTTPServer((hub.config.host, hub.config.port), _handler(hub))
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    log.info("viewer hub on http://%s:%d (run servers on %s%s)", hub.config.host, hub.config.port,
             hub.config.run_host, ", key required" if hub.config.key else "")
    try:
        while stop is None or not stop.is_set():
            time.sleep(0.2)
    finally:
        httpd.shutdown()
        hub.stop()


__all__ = ["KEY_HEADER", "HubConfig", "QuietHTTPServer", "RunServer", "ViewerHub", "reachable_host", "serve_hub"]
