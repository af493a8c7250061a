"""Property-based fuzzing of the api against its own OpenAPI spec (schemathesis).

Every operation gets the spec's examples, boundary values (coverage phase) and generated valid and
invalid requests (positive and negative modes), at most ``MAX_EXAMPLES`` fuzzed ones each, with a fixed
seed. Each response must be no 5xx, a documented status code and content type, headers and a body that
match the spec, and invalid requests must be refused. The ids the spec's examples use are seeded (a
sequence, a finished job with artifacts, a batch) and a stand-in viewer hub answers, so the examples
reach the success paths, not only 404s. A second app has an API token the fuzzer never knows: every
mutating request must be a documented 401, whatever else is wrong with it. Everything runs on SQLite
and on PostgreSQL (a fresh schema per app at 127.0.0.1:5432, skipped with the reason when unreachable),
with data dirs under pytest's temp dirs: nothing is written into the repository.
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest
import schemathesis
from fastapi import FastAPI
from schemathesis.checks import not_a_server_error
from schemathesis.python.asgi import shutdown_lifespans
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    negative_data_rejection,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)
from sqlalchemy.orm import sessionmaker

from backend.api.schemas import _BATCH_ID, _JOB_ID, _SEQ_ID
from backend.app import create_app
from storage.artifacts import ArtifactStore
from storage.db import init_db, make_engine, make_session_factory
from storage.models import Batch, JobStatus
from storage.repositories import jobs, sequences
from storage.settings import Settings, get_settings
from tests.backend.api.data import write_sequence
from tests.backends import pg_schema_url

# Per operation and mode: the file runs in well under a minute on 2 CPUs. A deeper run on demand:
# VTD_TEST_FUZZ_EXAMPLES=500 VTD_TEST_FUZZ_SEED=7 pytest tests/backend/api/test_fuzz.py
MAX_EXAMPLES = int(os.environ.get("VTD_TEST_FUZZ_EXAMPLES", "25"))
SEED = int(os.environ.get("VTD_TEST_FUZZ_SEED", "20261122"))
TOKEN = "fuzz-token"
CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    negative_data_rejection,
]
MUTATING = ["POST", "PUT", "PATCH", "DELETE"]


def _config() -> schemathesis.Config:
    return schemathesis.Config.from_dict({
        "seed": SEED,
        "generation": {"max-examples": MAX_EXAMPLES, "deterministic": True, "mode": "all", "database": "none"},
        "request-timeout": 30,
        "max-stream-events": 5,  # the events endpoint streams; a few events are enough to check
    })


def _spec_schema(**settings: object) -> schemathesis.BaseSchema:
    """The spec of an app with ``settings``, read without serving a request (no engine, no data dir)."""
    unused = Path(tempfile.gettempdir()) / "vtd-fuzz-spec-only"  # never the repo, even if something writes
    spec_app = create_app(get_settings(data_dir=unused, **settings), enqueue=lambda _id: None,
                          session_factory=sessionmaker(), migrate=False)
    schema = schemathesis.openapi.from_dict(spec_app.openapi(), config=_config())
    schema.app = spec_app  # selects the in-process ASGI transport; each test passes its own app
    return schema


open_schema = _spec_schema()
secured_schema = _spec_schema(api_token=TOKEN)


@pytest.fixture(scope="module")
def viewer_hub() -> Iterator[int]:
    """A stand-in for the viewer hub (``vtdslam viewer``): every run "opens" on port 40123."""

    class Hub(BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 (http.server's naming)
            body = json.dumps({"port": 40123}).encode()
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Hub)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server.server_address[1]
    server.shutdown()
    server.server_close()


def _seed(settings: Settings) -> None:
    """A sequence, a batch and a succeeded job with artifacts, under the ids of the spec's examples."""
    store = ArtifactStore(settings.data_dir)
    folder = store.install_sequence(write_sequence(settings.data_dir.parent / "seed", n=3), _SEQ_ID)
    engine = make_engine(settings)
    try:
        init_db(engine)
        with make_session_factory(engine)() as session:
            sequences.create(session, id=_SEQ_ID, name="seed", path=store.relative(folder), frames=3,
                             camera={"preset": "tum1"}, meta={"thumbnail": "rgb/" + min(
                                 p.name for p in (folder / "rgb").iterdir())})
            session.add(Batch(id=_BATCH_ID, name="seed", sequence_ids=[_SEQ_ID], presets=["orb-only"]))
            session.flush()
            job = jobs.new_job(sequence_id=_SEQ_ID, preset="orb-only", config=None, batch_id=_BATCH_ID)
            job.id = _JOB_ID
            session.add(job)
            session.commit()
            jobs.finish(session, _JOB_ID, JobStatus.SUCCEEDED)
    finally:
        engine.dispose()
    store.write_text(_JOB_ID, "trajectory.txt", "100.0 0 0 0 0 0 0 1\n")
    store.write_text(_JOB_ID, "metrics.json", '{"frames": 3}')


def _app(tmp: Path, viewer_port: int, database: str, **settings: object) -> Iterator[FastAPI]:
    """An app on its own temp data dir and, for PostgreSQL, its own schema (dropped afterwards)."""
    root = tmp / "imports"
    write_sequence(root / "tum" / "seq_a", n=3)
    with contextlib.ExitStack() as stack:
        url = stack.enter_context(pg_schema_url()) if database == "postgresql" else None
        s = get_settings(data_dir=tmp / "data", import_root=root, viewer_port=viewer_port,
                         max_upload_bytes=1 << 20, database_url=url, **settings)
        _seed(s)
        app = create_app(s, enqueue=lambda _id: None)
        yield app
        shutdown_lifespans()  # schemathesis keeps an app's lifespan running until told
        app.state.session_factory.kw["bind"].dispose()  # before the schema is dropped


# Module scope: one app per run, its state carried from one generated request to the next (as a real
# client's would be); hypothesis rightly refuses function-scoped fixtures inside @given. Both databases:
# NUL bytes and NaN were 500s on PostgreSQL only.
@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def database(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture(scope="module")
def open_app(tmp_path_factory: pytest.TempPathFactory, viewer_hub: int, database: str) -> Iterator[FastAPI]:
    yield from _app(tmp_path_factory.mktemp("fuzz-open"), viewer_hub, database)


@pytest.fixture(scope="module")
def secured_app(tmp_path_factory: pytest.TempPathFactory, viewer_hub: int, database: str) -> Iterator[FastAPI]:
    yield from _app(tmp_path_factory.mktemp("fuzz-secured"), viewer_hub, database, api_token=TOKEN)


@open_schema.exclude(method="DELETE").parametrize()
def test_api_conforms_to_its_spec(case: schemathesis.Case, open_app: FastAPI) -> None:
    case.call_and_validate(checks=CHECKS, app=open_app)


@open_schema.include(method="DELETE").parametrize()
def test_deletes_conform_to_the_spec(case: schemathesis.Case, open_app: FastAPI) -> None:
    """After the rest: deleting the seeded resources first would leave the other operations only 404s."""
    case.call_and_validate(checks=CHECKS, app=open_app)


@secured_schema.include(method=MUTATING).parametrize()
def test_mutations_without_the_token_are_401_as_documented(case: schemathesis.Case, secured_app: FastAPI) -> None:
    response = case.call_and_validate(checks=CHECKS, app=secured_app)
    if case.method.upper() == case.operation.method.upper():  # not the coverage phase's wrong-method probes
        assert response.status_code == 401, (case.method, case.path, response.status_code)
