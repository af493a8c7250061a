"""Hostile JSON, ids and names (issue 24, rows 4-7), on SQLite and PostgreSQL: each a 4xx in the error
shape with a request id, no row written, no server path or SQL in the answer, listings healthy after."""
from __future__ import annotations

import json
import tarfile
import tracemalloc
from collections.abc import Iterator
from typing import Any

import pytest
import sqlalchemy.exc
from fastapi.testclient import TestClient

from backend.app import create_app
from storage.repositories import sequences
from storage.settings import Settings, get_settings
from tests.backend.api.conftest import RecordingQueue, leftovers, upload
from tests.backend.api.data import tar_gz, write_sequence
from tests.backends import pg_schema_url
from tests.storage.ingest.bombs import header_bomb

DEEP = 255


@pytest.fixture(params=["sqlite", "postgresql"])
def env(request, tmp_path) -> Iterator[tuple[TestClient, Settings]]:
    def build(url: str | None) -> Iterator[tuple[TestClient, Settings]]:
        settings = get_settings(data_dir=tmp_path / "data", database_url=url, import_root=tmp_path / "imports")
        (tmp_path / "imports").mkdir()
        with TestClient(create_app(settings, enqueue=RecordingQueue()), raise_server_exceptions=False) as c:
            yield c, settings

    if request.param == "sqlite":
        yield from build(None)
    else:
        with pg_schema_url() as url:
            yield from build(url)


@pytest.fixture
def seq_id(env, seq_tgz) -> str:
    client, _ = env
    r = upload(client, seq_tgz)
    assert r.status_code == 201, r.text
    return r.json()["id"]


def _nested(depth: int) -> dict[str, Any]:
    value: dict[str, Any] = {"x": 1}
    for _ in range(depth - 1):
        value = {"a": value}
    return value


def assert_refused(client: TestClient, r: Any, status: int, fragment: str = "") -> None:
    assert r.status_code == status, r.text
    err = r.json()["error"]
    assert err["request_id"] == r.headers["x-request-id"] and len(err["request_id"]) == 32
    assert fragment.lower() in err["message"].lower(), err
    assert "INSERT" not in r.text and "SELECT" not in r.text and "/tmp" not in r.text
    for listing in ("/api/v1/jobs", "/api/v1/sequences", "/api/v1/batches"):
        assert client.get(listing).status_code == 200


def _post(client: TestClient, path: str, text: str) -> Any:
    return client.post(path, content=text.encode(), headers={"Content-Type": "application/json"})


@pytest.mark.parametrize("config, fragment", [
    (json.dumps(_nested(DEEP)), "nested deeper"),
    ('{"features.n_features": NaN}', "NaN"),
    ('{"features.n_features": Infinity}', "Infinity"),
    ('{"features.n_features": -Infinity}', "Infinity"),
    ('{"features.n_features": 1e400}', "finite"),
    ('{"name\\u0000x": 1}', "NUL"),
    ('{"x": "a\\u0000b"}', "NUL"),
    ('{"x": 123456789012345678901234567890}', "64 bits"),
])
def test_hostile_job_and_batch_configs_are_422_and_create_nothing(env, seq_id, config, fragment) -> None:
    client, _ = env
    r = _post(client, "/api/v1/jobs", f'{{"sequence_id": "{seq_id}", "preset": "orb-only", "config": {config}}}')
    assert_refused(client, r, 422, fragment)
    r = _post(client, "/api/v1/batches",
              f'{{"sequence_ids": ["{seq_id}"], "presets": ["orb-only"], "config": {config}}}')
    assert_refused(client, r, 422, fragment)
    assert client.get("/api/v1/jobs").json()["total"] == 0
    assert client.get("/api/v1/batches").json()["items"] == []


@pytest.mark.parametrize("path, status", [
    ("/api/v1/jobs/a%00b", 404),
    ("/api/v1/jobs/a%00b/events", 404),
    ("/api/v1/jobs/a%00b/artifacts/trajectory.txt", 404),
    ("/api/v1/jobs/a%00b/frames", 404),
    ("/api/v1/sequences/a%00b", 404),
    ("/api/v1/sequences/a%00b/thumbnail", 404),
    ("/api/v1/batches/a%00b", 404),
    ("/api/v1/batches/a%00b/table", 404),
    ("/api/v1/jobs?sequence_id=a%00b", 422),
    ("/api/v1/jobs?batch_id=%00", 422),
    ("/api/v1/jobs?status=%00", 422),
])
def test_nul_in_ids_and_filters_is_refused_before_any_query(env, path, status) -> None:
    client, _ = env
    assert_refused(client, client.get(path), status)
    if "?" not in path:  # before routing: even a method the route lacks gets the 404
        assert_refused(client, client.delete(path), 404)


def test_nul_in_body_ids_is_422(env, seq_id) -> None:
    client, _ = env
    r = _post(client, "/api/v1/jobs", '{"sequence_id": "a\\u0000b", "preset": "orb-only"}')
    assert_refused(client, r, 422, "NUL")
    r = _post(client, "/api/v1/batches", '{"sequence_ids": ["\\u0000"], "presets": ["orb-only"]}')
    assert_refused(client, r, 422, "NUL")


@pytest.mark.parametrize("form", [{"name": "a\x00b"}, {"camera": "tum1\x00"}])
def test_nul_in_upload_fields_is_422_without_sql(env, seq_tgz, form) -> None:
    client, settings = env
    r = client.post("/api/v1/sequences", files={"file": ("seq.tgz", seq_tgz, "application/gzip")},
                    data={"camera": "tum1", **form})
    assert_refused(client, r, 422, "NUL")
    assert client.get("/api/v1/sequences").json()["total"] == 0 and leftovers(settings) == []


def test_nul_in_upload_filename_is_422_without_sql(env, seq_tgz) -> None:
    client, settings = env
    boundary = b"vtdboundary"  # written by hand: httpx would escape the NUL as %00
    body = (b"--" + boundary + b'\r\nContent-Disposition: form-data; name="camera"\r\n\r\ntum1\r\n--' + boundary
            + b'\r\nContent-Disposition: form-data; name="file"; filename="se\x00q.tgz"\r\n'
            + b"Content-Type: application/gzip\r\n\r\n" + seq_tgz + b"\r\n--" + boundary + b"--\r\n")
    r = client.post("/api/v1/sequences", content=body,
                    headers={"Content-Type": "multipart/form-data; boundary=vtdboundary"})
    assert_refused(client, r, 422, "NUL")
    assert client.get("/api/v1/sequences").json()["total"] == 0 and leftovers(settings) == []


@pytest.mark.parametrize("camera, fragment", [
    ('{"fx": NaN, "fy": 500, "cx": 320, "cy": 240}', "NaN"),
    ('{"fx": Infinity, "fy": 500, "cx": 320, "cy": 240}', "Infinity"),
    ('{"fx": 1e400, "fy": 500, "cx": 320, "cy": 240}', "finite"),
    ('{"a": ' * 5000 + "1" + "}" * 5000, "nested deeper"),
])
def test_hostile_camera_json_on_upload_and_import(env, seq_tgz, seq_folder, camera, fragment) -> None:
    client, settings = env
    assert_refused(client, upload(client, seq_tgz, camera=camera), 422, fragment)
    (settings.import_root / "seq").symlink_to(seq_folder)
    body = f'{{"path": "seq", "camera": {camera}}}'
    assert_refused(client, _post(client, "/api/v1/sequences/import", body), 422, fragment)
    assert client.get("/api/v1/sequences").json()["total"] == 0 and leftovers(settings) == []


def test_camera_json_nested_5000_deep_inside_the_upload(env, tmp_path) -> None:
    client, settings = env
    folder = write_sequence(tmp_path / "deep" / "seq", n=4, camera_json=False)
    (folder / "camera.json").write_text("[" * 5000 + "]" * 5000)
    data = tar_gz(folder, tmp_path / "deep.tgz", top="seq").read_bytes()
    assert_refused(client, upload(client, data), 422, "camera.json")
    assert client.get("/api/v1/sequences").json()["total"] == 0 and leftovers(settings) == []


def test_a_database_error_answers_500_with_a_request_id_and_no_sql(env, seq_tgz, monkeypatch, caplog) -> None:
    client, settings = env

    def refuse(*_a: Any, **_k: Any) -> None:
        raise sqlalchemy.exc.DataError("INSERT INTO sequences (id, name) VALUES (%s, %s)", ("x", "y"),
                                       ValueError(f"bad byte in {settings.data_dir.resolve()}"))

    monkeypatch.setattr(sequences, "create", refuse)
    r = upload(client, seq_tgz)
    assert r.status_code == 500
    err = r.json()["error"]
    assert err == {"code": "error", "message": "internal server error", "detail": None,
                   "request_id": r.headers["x-request-id"]}
    assert err["request_id"] in caplog.text and "INSERT INTO" in caplog.text  # the server log has it all
    assert leftovers(settings) == []


@pytest.mark.parametrize("config, fragment", [
    ({"features.n_levels": 0}, "features.n_levels must be within 1..16"),
    ({"features": {"n_levels": 0}}, "features.n_levels must be within 1..16"),
    ({"tracking.ratio": 7}, "tracking.ratio must be within 0.1..1.0"),
    ({"features.n_features": 1e12}, "features.n_features must be within 10..100000"),
    ({"features.n_levels": 2.5}, "features.n_levels must be an integer"),
    ({"features.n_levels": "8"}, "features.n_levels must be an integer"),
    ({"features.n_levelz": 8}, "unknown config field"),
    ({"segmentation": {"segmenter": {"dynamic_classes": ["person", "forklift"]}}}, "unknown name 'forklift'"),
    ({"segmentation.segmenter.dynamic_classes": "vehicle,unicorn"}, "unknown name 'unicorn'"),
    ({"segmentation.segmenter.dynamic_classes": [3]}, "must be a list of names"),
])
def test_settings_out_of_range_are_422_naming_field_and_range(env, seq_id, config, fragment) -> None:
    client, _ = env
    r = client.post("/api/v1/jobs", json={"sequence_id": seq_id, "preset": "orb-only", "config": config})
    assert_refused(client, r, 422, fragment)
    r = client.post("/api/v1/batches", json={"sequence_ids": [seq_id], "presets": ["orb-only"], "config": config})
    assert_refused(client, r, 422, fragment)
    assert client.get("/api/v1/jobs").json()["total"] == 0


@pytest.fixture(scope="module")
def pax_bomb() -> bytes:
    return header_bomb(tarfile.XHDTYPE, 400 << 20)


def test_the_408_kb_pax_bomb_upload_is_4xx_with_memory_flat(env, pax_bomb) -> None:
    client, settings = env
    tracemalloc.start()
    try:
        r = upload(client, pax_bomb)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert_refused(client, r, 413, "PAX or GNU long name")
    assert peak < 100 << 20, f"{peak / 1e6:.0f} MB"  # the api went from 157 MB to 1.67 GB
    assert client.get("/api/v1/sequences").json()["total"] == 0 and leftovers(settings) == []
