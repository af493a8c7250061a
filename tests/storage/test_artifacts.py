from pathlib import Path

import pytest

from storage.artifacts import ArtifactInfo, ArtifactStore, check_name, make_artifact_store
from storage.errors import Conflict, InvalidInput, NotFound
from storage.settings import Settings


@pytest.fixture
def store(settings: Settings) -> ArtifactStore:
    return make_artifact_store(settings)


def test_layout(store: ArtifactStore, settings: Settings) -> None:
    assert store.root == settings.data_dir
    assert store.job_dir("j1") == settings.data_dir / "artifacts" / "j1"
    assert store.sequence_dir("s1") == settings.data_dir / "sequences" / "s1"
    assert store.staging_dir() == settings.data_dir / "staging" and store.staging_dir().is_dir()


def test_write_read_list(store: ArtifactStore) -> None:
    store.write_text("j1", "trajectory.txt", "0 0 0 0 0 0 0 1\n")
    with store.open_write("j1", "map.ply") as fh:
        fh.write(b"ply\n")
    assert store.path("j1", "trajectory.txt").read_text() == "0 0 0 0 0 0 0 1\n"
    assert store.path("j1", "map.ply").read_bytes() == b"ply\n"
    assert store.list("j1") == [ArtifactInfo("map.ply", 4), ArtifactInfo("trajectory.txt", 16)]
    assert store.list("never-ran") == []


def test_write_is_atomic(store: ArtifactStore) -> None:
    store.write_bytes("j1", "metrics.json", b'{"old": 1}')
    with pytest.raises(RuntimeError):
        with store.open_write("j1", "metrics.json") as fh:
            fh.write(b'{"new": ')
            # mid-write, readers still see the old complete file under the name
            assert store.path("j1", "metrics.json").read_bytes() == b'{"old": 1}'
            raise RuntimeError("crash while writing")
    assert store.path("j1", "metrics.json").read_bytes() == b'{"old": 1}'
    assert sorted(p.name for p in store.job_dir("j1").iterdir()) == ["metrics.json"]  # no temp left


def test_put_file(store: ArtifactStore, tmp_path: Path) -> None:
    src = tmp_path / "cloud.ply"
    src.write_bytes(b"x" * 3_000_000)
    assert store.put_file("j1", "map.ply", src).read_bytes() == src.read_bytes()


@pytest.mark.parametrize("name", ["../x", "a/b", "a\\b", "..", ".", "", ".hidden", "x\0y", "/etc/passwd"])
def test_bad_names_rejected(store: ArtifactStore, name: str) -> None:
    with pytest.raises(InvalidInput):
        check_name(name)
    with pytest.raises(InvalidInput):
        store.path("j1", name)
    with pytest.raises(InvalidInput):
        store.write_bytes("j1", name, b"x")


@pytest.mark.parametrize("job_id", ["..", "../etc", "a/b", ""])
def test_bad_ids_rejected(store: ArtifactStore, job_id: str) -> None:
    with pytest.raises(InvalidInput):
        store.job_dir(job_id)
    with pytest.raises(InvalidInput):
        store.sequence_dir(job_id)


def test_missing_artifact(store: ArtifactStore) -> None:
    with pytest.raises(NotFound):
        store.path("j1", "map.ply")
    store.job_dir("j1", create=True).joinpath("sub").mkdir()
    with pytest.raises(NotFound):  # a directory is not an artifact
        store.path("j1", "sub")


def test_delete(store: ArtifactStore) -> None:
    store.write_bytes("j1", "a.txt", b"1")
    store.delete_job("j1")
    store.delete_job("j1")  # idempotent
    assert not store.job_dir("j1").exists()
    store.sequence_dir("s1").mkdir(parents=True)
    store.delete_sequence("s1")
    assert not store.sequence_dir("s1").exists()


def test_staging_install_and_paths(store: ArtifactStore) -> None:
    staged = store.new_staging_dir()
    assert staged.parent == store.staging_dir() and staged != store.new_staging_dir()
    (staged / "rgb.txt").write_text("# rgb\n")
    dest = store.install_sequence(staged, "s1")
    assert dest == store.sequence_dir("s1") and (dest / "rgb.txt").is_file() and not staged.exists()
    assert store.relative(dest) == "sequences/s1"
    assert store.resolve("sequences/s1") == dest
    assert store.resolve("/srv/data/x") == Path("/srv/data/x")
    other = store.new_staging_dir()
    with pytest.raises(Conflict):
        store.install_sequence(other, "s1")


def test_relative_outside_root_stays_absolute(store: ArtifactStore, tmp_path: Path) -> None:
    assert store.relative(tmp_path / "elsewhere") == str((tmp_path / "elsewhere").resolve())


def test_store_is_plain_object(tmp_path: Path) -> None:
    assert ArtifactStore(tmp_path).root == tmp_path
