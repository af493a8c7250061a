"""Health, OpenAPI, and the one error shape for routing mistakes."""
from __future__ import annotations

from formats.version import package_version


def test_health(client):
    r = client.get("/api/v1/health")
    assert r.status_code == 200
    assert r.json() == {"status": "ok", "version": package_version(), "database": "ok"}


def test_openapi_lists_every_endpoint_with_examples(client):
    spec = client.get("/openapi.json").json()
    paths = spec["paths"]
    for path, method in [("/api/v1/sequences", "post"), ("/api/v1/sequences/import", "post"),
                         ("/api/v1/jobs", "post"), ("/api/v1/jobs/{job_id}/events", "get"),
                         ("/api/v1/jobs/{job_id}/artifacts/{name}", "get"),
                         ("/api/v1/batches/{batch_id}/table", "get")]:
        assert method in paths[path], (path, method)
    upload = paths["/api/v1/sequences"]["post"]["requestBody"]["content"]["multipart/form-data"]["schema"]
    assert set(upload["required"]) == {"file", "camera"}
    assert spec["components"]["schemas"]["JobOut"]["examples"]
    assert "HTTPBearer" in spec["components"]["securitySchemes"]


def test_unknown_route_and_wrong_method_use_the_error_shape(client):
    r = client.get("/api/v1/nope")
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"
    r = client.put("/api/v1/health")
    assert r.status_code == 405 and r.json()["error"]["code"] == "method_not_allowed"


def test_malformed_json_is_a_422_not_a_500(client):
    r = client.post("/api/v1/jobs", content=b"{not json", headers={"content-type": "application/json"})
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_input"
