from pathlib import Path

import pytest
from pydantic import ValidationError

from storage.settings import Settings, get_settings


def test_defaults() -> None:
    s = get_settings()
    assert s.data_dir == Path("data")
    assert s.database_url is None and s.queue_url is None and s.api_token is None
    assert s.resolved_database_url == "sqlite:///data/vtdslam.db"
    assert s.queue_path == Path("data/queue.db")
    assert s.shared_dir == Path("../shared") and s.import_root is None
    assert (s.max_upload_bytes, s.max_files, s.max_ratio) == (4 * 1024**3, 200_000, 200)
    assert (s.host, s.port, s.viewer_port) == ("127.0.0.1", 8000, 8080)


def test_from_env(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("VTD_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("VTD_QUEUE_URL", "redis://cache:6379/0")
    monkeypatch.setenv("VTD_API_TOKEN", "s3cret")
    monkeypatch.setenv("VTD_IMPORT_ROOT", "/srv/datasets")
    monkeypatch.setenv("VTD_MAX_FILES", "10")
    monkeypatch.setenv("VTD_PORT", "9000")
    s = get_settings()
    assert s.data_dir == tmp_path
    assert s.resolved_database_url == f"sqlite:///{tmp_path}/vtdslam.db"
    assert s.queue_url == "redis://cache:6379/0"
    assert s.api_token == "s3cret"
    assert s.import_root == Path("/srv/datasets")
    assert s.max_files == 10 and s.port == 9000


def test_database_url_from_env_wins_over_default(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("VTD_DATABASE_URL", "postgresql://u@db/vtd")
    assert get_settings().resolved_database_url == "postgresql://u@db/vtd"


def test_overrides_win_over_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("VTD_PORT", "9000")
    assert get_settings(port=1234).port == 1234


def test_token_kept_out_of_repr() -> None:
    assert "hunter2" not in repr(get_settings(api_token="hunter2"))


@pytest.mark.parametrize("bad", [{"port": 0}, {"max_files": 0}, {"max_upload_bytes": -1}])
def test_invalid_values_rejected(bad: dict) -> None:
    with pytest.raises(ValidationError):
        Settings(**bad)


def test_unknown_override_rejected() -> None:
    with pytest.raises(ValidationError):
        get_settings(data_dri="typo")


def test_unknown_env_ignored(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("VTD_SOMETHING_ELSE", "1")
    assert get_settings().port == 8000


def test_each_call_builds_a_new_object() -> None:
    assert get_settings() is not get_settings()
