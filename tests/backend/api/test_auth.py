"""Auth and exposure.

With VTD_API_TOKEN set, every mutating route (enumerated from the app's routes, not from a hand-kept list)
answers 401 to a missing or wrong token *before it reads the body*, and works with the right one; the
token decision is hmac.compare_digest's alone; neither the token nor a database password reaches the logs
or ``repr(settings)``; ``POST /sequences/import`` stays inside the import root; CORS is off unless configured.
"""
from __future__ import annotations

import hmac
import logging
import os
import socket
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import uvicorn
from fastapi import FastAPI
from fastapi.routing import APIRoute
from fastapi.testclient import TestClient
from uvicorn.logging import AccessFormatter, DefaultFormatter

import backend.api.deps as deps
from backend.app import create_app
from storage.db import make_engine, make_session_factory
from storage.settings import Settings, get_settings
from tests.backend.api.conftest import leftovers, upload
from tests.backend.api.data import write_sequence

TOKEN = "s3cret-t0ken-f00"
GOOD = {"Authorization": f"Bearer {TOKEN}"}
MUTATING_METHODS = {"POST", "PUT", "PATCH", "DELETE"}


def api_routes(app: FastAPI) -> list[tuple[str, str, list[Any]]]:
    """(method, path, dependencies) of every route the app serves, included routers flattened.

    FastAPI >= 0.16x keeps included routers as lazy ``_IncludedRouter`` entries; older ones copy the
    routes into ``app.routes``. Both are walked, so a route hidden from the OpenAPI schema counts too.
    """
    out = []
    for route in app.routes:
        # each a route or FastAPI's private route context: duck-typed, both have .methods and .path
        contexts: Iterable[Any] = (route.effective_route_contexts() if hasattr(route, "effective_route_contexts")
                                   else [route])
        for ctx in contexts:
            original = getattr(ctx, "original_route", ctx)
            if isinstance(original, APIRoute):
                for method in ctx.methods:
                    out.append((method, ctx.path, list(original.dependencies)))
    return out


def mutating_routes(app: FastAPI) -> set[tuple[str, str]]:
    return {(m, p) for m, p, _ in api_routes(app) if m in MUTATING_METHODS}


def _concrete(path: str) -> str:
    return path.replace("{job_id}", "x").replace("{sequence_id}", "x")


@pytest.fixture
def secured(tmp_path: Path) -> Iterator[tuple[TestClient, Settings]]:
    settings = get_settings(data_dir=tmp_path / "data", api_token=TOKEN, import_root=tmp_path / "imports")
    with TestClient(create_app(settings, enqueue=lambda _id: None)) as c:
        yield c, settings


def _nothing_registered(client: TestClient, settings: Settings) -> None:
    assert client.get("/api/v1/sequences").json()["total"] == 0
    assert client.get("/api/v1/jobs").json()["total"] == 0
    assert client.get("/api/v1/batches").json()["items"] == []
    assert leftovers(settings) == []


# ---- every mutating route is guarded ------------------------------------------------------------------

def test_every_mutating_route_needs_the_token_and_the_spec_says_so(secured) -> None:
    client, _ = secured
    routes = api_routes(client.app)
    mutating = [(m, p, d) for m, p, d in routes if m in MUTATING_METHODS]
    assert len(mutating) >= 8  # sequences (3), jobs (4), batches (1): the walk found the routers
    for method, path, dependencies in mutating:
        assert any(d.dependency is deps.require_token for d in dependencies), (method, path)
    spec = client.app.openapi()["paths"]
    for method, path in mutating_routes(client.app):
        assert spec[path][method.lower()]["security"] == [{"HTTPBearer": []}], (method, path)
        assert "401" in spec[path][method.lower()]["responses"], (method, path)


def test_without_a_token_the_spec_says_auth_is_optional(tmp_path) -> None:
    app = create_app(get_settings(data_dir=tmp_path / "d"), enqueue=lambda _id: None)
    with TestClient(app) as client:
        spec = client.get("/openapi.json").json()["paths"]  # what clients read, not only app.openapi()
    assert mutating_routes(app)
    for method, path in mutating_routes(app):
        assert spec[path][method.lower()]["security"] == [{"HTTPBearer": []}, {}], (method, path)


BAD_HEADERS = [
    None,
    "Bearer wrong",
    f"Basic {TOKEN}",
    TOKEN,
    "Bearer",
    "Bearer ",
    f"Bearer {TOKEN[:-1]}",  # a prefix
    f"Bearer {TOKEN}x",  # an extension
    f"Bearer {TOKEN.upper()}",
    f"Bearer {TOKEN} x",
    "Bearer t\u00f6ken".encode(),  # non-ASCII: compare_digest on str would raise (a 500); bytes compare cleanly
]


@pytest.mark.parametrize("header", BAD_HEADERS, ids=repr)
def test_missing_or_wrong_token_is_401_on_every_mutating_route(secured, header: str | bytes | None) -> None:
    client, settings = secured
    headers = {"Authorization": header} if header is not None else {}
    for method, path in sorted(mutating_routes(client.app)):
        r = client.request(method, _concrete(path), headers=headers)
        assert r.status_code == 401, (method, path, r.text)
        assert r.json()["error"]["code"] == "unauthorized" and r.headers["www-authenticate"] == "Bearer"
    _nothing_registered(client, settings)


@pytest.mark.parametrize("body", [
    b"{not json",
    b"\xff\xfe\x00garbage",
    b'{"sequence_id": "x", "preset": "orb-only", "extra": 1}',
    b"[" * 100_000,
    b" " * (2 << 20),  # over the JSON cap: still 401, and not read into memory past the cap
], ids=["bad-json", "not-utf8", "schema-violation", "deep-nesting", "2MiB"])
def test_the_token_is_checked_before_the_body_is_read(secured, body) -> None:
    """FastAPI parses a JSON body before dependencies: without the guard these were 400/422."""
    client, settings = secured
    for method, path in sorted(mutating_routes(client.app)):
        r = client.request(method, _concrete(path), content=body, headers={"Content-Type": "application/json"})
        assert r.status_code == 401, (method, path, r.status_code, r.text[:200])
    _nothing_registered(client, settings)


def test_json_bodies_are_capped_even_with_the_token(secured) -> None:
    client, settings = secured
    r = client.post("/api/v1/jobs", content=b'{"config": "' + b"x" * (2 << 20) + b'"}',
                    headers={**GOOD, "Content-Type": "application/json"})
    assert r.status_code == 413 and r.json()["error"]["code"] == "payload_too_large"
    _nothing_registered(client, settings)


def test_the_right_token_works_on_every_mutating_route(secured, seq_tgz) -> None:
    """One real request per mutating route, in an order that makes each succeed; a new mutating route
    fails this test until it has its own step."""
    client, settings = secured
    write_sequence(settings.import_root / "tum" / "seq_a", n=3)
    ids: dict[str, str] = {}

    def ok(r: Any, status: int) -> dict[str, Any]:
        assert r.status_code == status, r.text
        return r.json() if r.content else {}

    steps: dict[tuple[str, str], Callable[[], object]] = {
        ("POST", "/api/v1/sequences"): lambda: ids.update(seq=ok(upload(client, seq_tgz, headers=GOOD), 201)["id"]),
        ("POST", "/api/v1/sequences/import"): lambda: ids.update(imp=ok(client.post(
            "/api/v1/sequences/import", json={"path": "tum/seq_a", "camera": "tum1"}, headers=GOOD), 201)["id"]),
        ("POST", "/api/v1/jobs"): lambda: ids.update(job=ok(client.post(
            "/api/v1/jobs", json={"sequence_id": ids["seq"], "preset": "orb-only"}, headers=GOOD), 201)["id"]),
        ("POST", "/api/v1/jobs/{job_id}/cancel"): lambda: ok(client.post(
            f"/api/v1/jobs/{ids['job']}/cancel", headers=GOOD), 200),
        ("POST", "/api/v1/jobs/{job_id}/retry"): lambda: ok(client.post(
            f"/api/v1/jobs/{ids['job']}/retry", headers=GOOD), 200),
        ("DELETE", "/api/v1/jobs/{job_id}"): lambda: ok(client.delete(f"/api/v1/jobs/{ids['job']}", headers=GOOD), 204),
        ("POST", "/api/v1/batches"): lambda: ok(client.post(
            "/api/v1/batches", json={"sequence_ids": [ids["seq"], ids["imp"]], "presets": ["orb-only"]},
            headers=GOOD), 201),
        ("DELETE", "/api/v1/sequences/{sequence_id}"): lambda: ok(client.delete(
            f"/api/v1/sequences/{ids['seq']}", headers=GOOD), 204),
        ("POST", "/api/v1/live"): lambda: ok(client.post("/api/v1/live", json={"camera": "tum1"}, headers=GOOD), 201),
    }
    assert set(steps) == mutating_routes(client.app)
    for step in steps.values():
        step()
    assert client.get("/api/v1/sequences").json()["total"] == 2  # the imported one and the live session's are left
    # the scheme is case-insensitive (RFC 7235)
    assert client.delete(f"/api/v1/sequences/{ids['imp']}", headers={"Authorization": f"bearer {TOKEN}"}
                         ).status_code == 204


def test_compare_digest_alone_decides(secured, monkeypatch) -> None:
    """The token check goes through hmac.compare_digest (constant time) on bytes, and nothing else decides:
    forcing its answer flips the outcome for the right and the wrong token alike."""
    client, _ = secured
    seen: list[tuple[bytes, bytes]] = []

    def forced(answer: bool) -> SimpleNamespace:
        def compare_digest(a: bytes, b: bytes) -> bool:
            seen.append((a, b))
            return answer
        return SimpleNamespace(compare_digest=compare_digest)

    monkeypatch.setattr(deps, "hmac", forced(False))
    assert client.delete("/api/v1/jobs/x", headers=GOOD).status_code == 401
    monkeypatch.setattr(deps, "hmac", forced(True))
    assert client.delete("/api/v1/jobs/x", headers={"Authorization": "Bearer wrong"}).status_code == 404
    assert set(seen) == {(TOKEN.encode(), TOKEN.encode()), (b"wrong", TOKEN.encode())}  # guard and dependency
    monkeypatch.setattr(deps, "hmac", hmac)
    assert client.delete("/api/v1/jobs/x", headers={"Authorization": "Bearer wrong"}).status_code == 401


def test_reads_stay_open(secured) -> None:
    client, _ = secured
    for path in ("/api/v1/health", "/api/v1/sequences", "/api/v1/jobs", "/api/v1/batches", "/api/v1/presets"):
        assert client.get(path).status_code == 200, path


# ---- no secrets in logs --------------------------------------------------------------------------------

PASSWORD = "pg-Pa55word-9f3"


def _free_socket() -> socket.socket:
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    return sock


def _raw(port: int, request: str) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(request.encode())
        data = b""
        while chunk := s.recv(65536):
            data += chunk
    return data


def test_no_secrets_in_logs_or_repr(tmp_path, caplog) -> None:
    """A real uvicorn server (access log on, everything at DEBUG) on a database URL that carries a password;
    requests with a wrong and the right token, in the header and (wrongly) in the query string."""
    settings = get_settings(data_dir=tmp_path / "data", api_token=TOKEN,
                            database_url=f"postgresql://vtd:{PASSWORD}@127.0.0.1:1/vtd",
                            queue_url=f"redis://:{PASSWORD}@127.0.0.1:1/0")
    for text in (repr(settings), str(settings), f"{settings!r}"):
        assert TOKEN not in text and PASSWORD not in text and "***" in text
    # the app runs on SQLite (no PostgreSQL here); the settings it holds and could log carry the password
    engine = make_engine(get_settings(data_dir=tmp_path / "data"))
    caplog.set_level(logging.DEBUG)
    sock = _free_socket()
    # log_config=None: uvicorn configures no handlers of its own, so its records reach caplog's
    app = create_app(settings, enqueue=lambda _id: None, session_factory=make_session_factory(engine))
    server = uvicorn.Server(uvicorn.Config(app, log_config=None,
                                           log_level="debug", access_log=True, lifespan="on"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 20
        while not server.started:
            assert time.monotonic() < deadline and thread.is_alive()
            time.sleep(0.02)
        port = sock.getsockname()[1]
        for auth in ("Bearer wrong-token", f"Bearer {TOKEN}", f"Basic {TOKEN}"):
            reply = _raw(port, f"DELETE /api/v1/jobs/x HTTP/1.1\r\nHost: h\r\nAuthorization: {auth}\r\n"
                               "Connection: close\r\n\r\n")
            assert reply.split()[1] in (b"401", b"404")
            assert TOKEN.encode() not in reply and PASSWORD.encode() not in reply
        _raw(port, f"GET /api/v1/health HTTP/1.1\r\nHost: h\r\nAuthorization: Bearer {TOKEN}\r\n"
                   "Connection: close\r\n\r\n")
    finally:
        server.should_exit = True
        thread.join(10)
        sock.close()
        engine.dispose()
    access = AccessFormatter('%(levelprefix)s %(client_addr)s - "%(request_line)s" %(status_code)s')
    default = DefaultFormatter("%(levelprefix)s %(name)s %(message)s")
    lines = [(access if r.name == "uvicorn.access" else default).format(r) for r in caplog.records]
    assert sum(r.name == "uvicorn.access" for r in caplog.records) == 4  # the access log was captured
    assert any("DELETE /api/v1/jobs/x" in line and "401" in line for line in lines)
    for line in lines:
        assert TOKEN not in line and PASSWORD not in line, line


# ---- import-root confinement ---------------------------------------------------------------------------

@pytest.fixture
def importer(tmp_path: Path) -> Iterator[tuple[TestClient, Settings, Path]]:
    root = tmp_path / "imports"
    outside = write_sequence(tmp_path / "outside", n=3)
    write_sequence(root / "tum" / "seq_a", n=3)
    (root / "escape").symlink_to(outside, target_is_directory=True)  # a link inside the root, out of it
    linked = write_sequence(root / "tum" / "seq_linked_rgb", n=3)  # its rgb/ folder is a link out
    os.rename(linked / "rgb", tmp_path / "rgb_elsewhere")
    (linked / "rgb").symlink_to(tmp_path / "rgb_elsewhere", target_is_directory=True)
    (root / "loop").symlink_to(root / "loop")
    settings = get_settings(data_dir=tmp_path / "data", import_root=root)
    with TestClient(create_app(settings, enqueue=lambda _id: None)) as c:
        yield c, settings, tmp_path


TRAVERSALS = [
    ("../outside", 422),
    ("tum/../../outside", 422),
    ("tum/seq_a/../../../outside", 422),
    ("{tmp}/outside", 422),  # absolute, outside the root
    ("/etc", 422),
    ("/", 422),
    ("escape", 422),  # symlink in the root pointing out
    ("escape/", 422),
    ("tum/seq_linked_rgb", 422),  # the folder is inside, its rgb/ is a link out
    ("loop", 422),  # a symlink loop
    ("%2e%2e/outside", 404),  # JSON carries no URL encoding: a literal (missing) folder name
    ("%2e%2e%2foutside", 404),
    ("..%2foutside", 404),
    ("tum/seq_a\x00", 422),  # NUL byte
    ("\x00../outside", 422),
    ("a" * 1000, 422),  # name too long for the filesystem
    ("tum/missing", 404),
    ("~/outside", 404),
]


@pytest.mark.parametrize("path, status", TRAVERSALS, ids=repr)
def test_import_stays_inside_the_root(importer, path, status) -> None:
    client, settings, tmp = importer
    r = client.post("/api/v1/sequences/import", json={"path": path.format(tmp=tmp), "camera": "tum1"})
    assert r.status_code == status, r.text
    assert set(r.json()["error"]) == {"code", "message", "detail", "request_id"}
    assert client.get("/api/v1/sequences").json()["total"] == 0


def test_import_inside_the_root_works_relative_or_absolute(importer) -> None:
    """The control for the traversal table: the same fixture accepts the folder that really is inside."""
    client, settings, _ = importer
    assert client.post("/api/v1/sequences/import", json={"path": "tum/seq_a", "camera": "tum1"}).status_code == 201
    r = client.post("/api/v1/sequences/import",
                    json={"path": str(settings.import_root / "tum" / "./seq_a"), "camera": "tum1"})
    assert r.status_code == 201, r.text


# ---- CORS ----------------------------------------------------------------------------------------------

ORIGIN = "https://dashboard.example"


def _cors_client(tmp_path: Path, **kw: Any) -> TestClient:
    return TestClient(create_app(get_settings(data_dir=tmp_path / "d", **kw), enqueue=lambda _id: None))


def _preflight(client: TestClient, origin: str) -> Any:
    return client.options("/api/v1/jobs", headers={
        "Origin": origin, "Access-Control-Request-Method": "POST",
        "Access-Control-Request-Headers": "authorization, content-type"})


def test_cors_is_off_by_default(tmp_path) -> None:
    with _cors_client(tmp_path) as client:
        r = client.get("/api/v1/sequences", headers={"Origin": ORIGIN})
        assert r.status_code == 200 and "access-control-allow-origin" not in r.headers
        r = _preflight(client, ORIGIN)
        assert r.status_code >= 400 and not any(h.startswith("access-control-") for h in r.headers)


def test_cors_only_for_the_configured_origins(tmp_path) -> None:
    with _cors_client(tmp_path, cors_origins=[ORIGIN], api_token=TOKEN) as client:
        r = client.get("/api/v1/sequences", headers={"Origin": ORIGIN})
        assert r.headers["access-control-allow-origin"] == ORIGIN
        assert "access-control-allow-credentials" not in r.headers
        r = _preflight(client, ORIGIN)
        assert r.status_code == 200 and r.headers["access-control-allow-origin"] == ORIGIN
        assert {"authorization", "content-type"} <= {
            h.strip().lower() for h in r.headers["access-control-allow-headers"].split(",")}
        assert "POST" in r.headers["access-control-allow-methods"]
        other = "https://evil.example"
        assert "access-control-allow-origin" not in client.get("/api/v1/sequences", headers={"Origin": other}).headers
        assert "access-control-allow-origin" not in _preflight(client, other).headers
        # CORS opens reads to the origin, not writes to anyone: the token is still needed
        r = client.delete("/api/v1/jobs/x", headers={"Origin": ORIGIN})
        assert r.status_code == 401 and r.headers["access-control-allow-origin"] == ORIGIN


def test_cors_origins_from_the_environment(monkeypatch) -> None:
    monkeypatch.setenv("VTD_CORS_ORIGINS", f'["{ORIGIN}"]')
    assert get_settings().cors_origins == [ORIGIN]
