"""Issue 60.3: files the api may not read (an api and a worker under different users on shared storage).

Every read of them is a JSON error in the standard shape (code ``artifact_unreadable``), never a truncated
200 (the file is opened before any header goes out), and the viewer says so instead of "not running".
The fault: ``chmod 000`` where that blocks reads (not as root), else open/stat/scandir patched to raise
PermissionError below the folder, which is what the kernel does then.
"""
from __future__ import annotations

import builtins
import errno
import io
import os
import stat
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from storage.artifacts import ArtifactStore, file_mode
from tests.backend.api.data import tar_gz, write_sequence
from tests.webui.test_viewer import proxied_run

AS_ROOT = os.geteuid() == 0


@contextmanager
def _chmod_000(folders: list[Path]) -> Iterator[None]:
    modes = [f.stat().st_mode for f in folders]
    for f in folders:
        f.chmod(0)
    try:
        yield
    finally:
        for f, m in zip(folders, modes, strict=True):
            f.chmod(stat.S_IMODE(m))


@contextmanager
def _patched(folders: list[Path], monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    denied = tuple(str(f.resolve()) for f in folders)

    def guard(fn: Callable) -> Callable:  # noqa: ANN001
        def wrapper(path, *args, **kwargs):  # noqa: ANN001, ANN202
            if isinstance(path, str | os.PathLike) and os.path.abspath(os.fspath(path)).startswith(denied):
                raise PermissionError(errno.EACCES, "Permission denied", os.fspath(path))
            return fn(path, *args, **kwargs)
        return wrapper

    with monkeypatch.context() as m:
        for module, name in [(os, "open"), (os, "stat"), (os, "scandir"), (os, "listdir"), (builtins, "open"),
                             (io, "open")]:
            m.setattr(module, name, guard(getattr(module, name)))
        yield


@pytest.fixture(params=["chmod", "patched"])
def deny(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Callable:
    if request.param == "chmod" and AS_ROOT:
        pytest.skip("root reads files whatever their mode: the patched variant covers it")
    return (lambda folders: _chmod_000(folders)) if request.param == "chmod" else \
        (lambda folders: _patched(folders, monkeypatch))


@pytest.fixture
def seq_tgz(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    folder = write_sequence(tmp_path_factory.mktemp("seq") / "rgbd_dataset_unreadable", n=3)
    return tar_gz(folder, tmp_path_factory.mktemp("arch") / "seq.tgz", top="rgbd_dataset_unreadable").read_bytes()


def _unreadable(r, status: int = 500) -> None:  # noqa: ANN001
    assert r.status_code == status, (r.status_code, r.headers, r.content[:200])
    assert r.headers["content-type"] == "application/json", r.headers
    error = r.json()["error"]
    assert error["code"] == "artifact_unreadable" and "cannot read" in error["message"], error
    assert "/data/" not in error["message"]  # server paths stay redacted


def test_artifacts_are_written_readable_like_sequences(tmp_path: Path) -> None:
    """mkstemp's 0600 hid every artifact from an api of another user; now 0666 minus the umask."""
    old = os.umask(0o022)
    try:
        file_mode.cache_clear()
        path = ArtifactStore(tmp_path).write_text("job1", "trajectory.txt", "1 0 0 0 0 0 0 1\n")
        assert stat.S_IMODE(path.stat().st_mode) == 0o644
    finally:
        os.umask(old)
        file_mode.cache_clear()


def test_unreadable_run_files_are_clear_errors(tmp_path: Path, seq_tgz: bytes, deny: Callable) -> None:
    with proxied_run(tmp_path, seq_tgz) as (client, job_id):
        store = ArtifactStore(tmp_path / "data")
        seq_id = client.get(f"/api/v1/jobs/{job_id}").json()["sequence_id"]
        seq_dir = store.sequence_dir(seq_id)  # where an upload is installed
        assert seq_dir.is_dir()
        assert client.get(f"/api/v1/jobs/{job_id}/artifacts/map.ply").status_code == 200  # the control
        with deny([store.job_dir(job_id), seq_dir]):
            _unreadable(client.get(f"/api/v1/jobs/{job_id}/artifacts"))
            for name in ("map.ply", "trajectory.txt"):
                _unreadable(client.get(f"/api/v1/jobs/{job_id}/artifacts/{name}"))
                r = client.head(f"/api/v1/jobs/{job_id}/artifacts/{name}")
                assert r.status_code == 500 and r.headers["content-type"] == "application/json"
            _unreadable(client.get(f"/api/v1/sequences/{seq_id}/thumbnail"))
            r = client.get(f"/api/v1/jobs/{job_id}/viewer")  # the hub is alive: it says what is wrong
            _unreadable(r)
            assert "3D viewer" in r.json()["error"]["message"]


def test_a_file_unreadable_after_listing_is_never_a_truncated_200(tmp_path: Path, seq_tgz: bytes) -> None:
    """Only the file is unreadable (its folder lists and stats): it is opened before the headers go out,
    so a JSON 500, not a 200 with its Content-Length and no body."""
    with proxied_run(tmp_path, seq_tgz) as (client, job_id):
        path = ArtifactStore(tmp_path / "data").job_dir(job_id) / "map.ply"
        with _chmod_000([path]) if not AS_ROOT else _only_open(path):
            listed = client.get(f"/api/v1/jobs/{job_id}/artifacts").json()
            assert "map.ply" in [a["name"] for a in listed]
            _unreadable(client.get(f"/api/v1/jobs/{job_id}/artifacts/map.ply"))
            _unreadable(client.get(f"/api/v1/jobs/{job_id}/artifacts/map.ply", headers={"Range": "bytes=0-9"}))


@contextmanager
def _only_open(path: Path) -> Iterator[None]:
    """As root: only opening the file fails (stat works, as for a 0000 file of another user)."""
    def guard(real: Callable) -> Callable:
        def guarded(p, *args, **kwargs):  # noqa: ANN001, ANN202
            if isinstance(p, str | os.PathLike) and os.fspath(p) == str(path):
                raise PermissionError(errno.EACCES, "Permission denied", os.fspath(p))
            return real(p, *args, **kwargs)
        return guarded

    with pytest.MonkeyPatch.context() as m:
        for module in (os, builtins, io):
            m.setattr(module, "open", guard(module.open))
        yield
