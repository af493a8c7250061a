"""With VTD_API_TOKEN set, every mutating endpoint needs the bearer token; reads stay open."""
from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from storage.settings import get_settings
from tests.backend.api.conftest import leftovers, upload

MUTATING = [
    ("post", "/api/v1/sequences"),
    ("post", "/api/v1/sequences/import"),
    ("delete", "/api/v1/sequences/x"),
    ("post", "/api/v1/jobs"),
    ("post", "/api/v1/jobs/x/cancel"),
    ("post", "/api/v1/jobs/x/retry"),
    ("delete", "/api/v1/jobs/x"),
    ("post", "/api/v1/batches"),
]


@pytest.fixture
def secured(tmp_path):
    settings = get_settings(data_dir=tmp_path / "data", api_token="s3cret")
    with TestClient(create_app(settings, enqueue=lambda _id: None)) as c:
        yield c, settings


def test_every_mutating_route_is_covered(secured):
    client, _ = secured
    paths = client.app.openapi()["paths"]
    found = {(m, p.replace("{job_id}", "x").replace("{sequence_id}", "x"))
             for p, ops in paths.items() for m in ops if m in ("post", "put", "patch", "delete")}
    assert found == set(MUTATING)
    for p, ops in paths.items():  # and the docs say so
        for m, op in ops.items():
            if m in ("post", "put", "patch", "delete"):
                assert op.get("security") == [{"HTTPBearer": []}], (m, p)


@pytest.mark.parametrize("method, path", MUTATING)
@pytest.mark.parametrize("header", [None, "Bearer wrong", "Basic s3cret", "s3cret"])
def test_missing_or_wrong_token_is_401(secured, method, path, header):
    client, settings = secured
    headers = {"Authorization": header} if header else {}
    r = getattr(client, method)(path, headers=headers)
    assert r.status_code == 401, r.text
    assert r.json()["error"]["code"] == "unauthorized" and r.headers["www-authenticate"] == "Bearer"
    assert leftovers(settings) == []


def test_right_token_works_and_reads_are_open(secured, seq_tgz):
    client, _ = secured
    assert client.get("/api/v1/sequences").status_code == 200
    assert upload(client, seq_tgz).status_code == 401
    r = upload(client, seq_tgz, headers={"Authorization": "Bearer s3cret"})
    assert r.status_code == 201, r.text
    assert client.get(f"/api/v1/sequences/{r.json()['id']}").status_code == 200
