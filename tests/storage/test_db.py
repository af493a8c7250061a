import threading
from pathlib import Path

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import Engine, inspect, text
from sqlalchemy.orm import Session, sessionmaker

from storage.db import alembic_config, init_db, make_engine, make_session_factory, normalize_url
from storage.errors import ConfigurationError
from storage.models import Base
from storage.settings import Settings

TABLES = {"sequences", "jobs", "batches", "run_metrics", "frame_stats", "alembic_version"}


def test_sqlite_pragmas(settings: Settings) -> None:
    engine = make_engine(settings)
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
        assert conn.exec_driver_sql("PRAGMA busy_timeout").scalar() == 30_000
    assert (settings.data_dir / "vtdslam.db").exists()  # the data dir was created for it
    engine.dispose()


def test_sqlite_engine_usable_across_threads(settings: Settings) -> None:
    engine = make_engine(settings)
    conn = engine.connect()
    out: list[object] = []
    t = threading.Thread(target=lambda: out.append(conn.execute(text("SELECT 1")).scalar()))
    t.start()
    t.join()
    assert out == [1]  # check_same_thread=False
    conn.close()
    engine.dispose()


@pytest.mark.parametrize(
    ("url", "driver"),
    [
        ("postgresql://u@h/db", "postgresql+psycopg"),
        ("postgres://u@h/db", "postgresql+psycopg"),
        ("postgresql+psycopg://u@h/db", "postgresql+psycopg"),
        ("sqlite:///x.db", "sqlite"),
    ],
)
def test_normalize_url(url: str, driver: str) -> None:
    assert normalize_url(url).drivername == driver


def test_bad_url() -> None:
    with pytest.raises(ConfigurationError):
        normalize_url("not a url")


def test_migrations_create_all_tables(engine: Engine) -> None:
    assert TABLES <= set(inspect(engine).get_table_names())
    with engine.connect() as conn:
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == "0005_sequence_content_claim"


def test_migrations_match_models(engine: Engine) -> None:
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn, opts={"compare_type": True}), Base.metadata)
    assert diff == []


def test_init_db_is_idempotent_and_accepts_settings(db_settings: Settings) -> None:
    init_db(db_settings)
    init_db(db_settings)
    engine = make_engine(db_settings)
    assert TABLES <= set(inspect(engine).get_table_names())
    engine.dispose()


def test_foreign_keys_back_on_after_migration(settings: Settings) -> None:
    engine = make_engine(settings, pool_size=1, max_overflow=0)  # init_db's connection is reused
    init_db(engine)
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
    engine.dispose()


def test_downgrade_and_upgrade_again(engine: Engine) -> None:
    with engine.begin() as conn:
        command.downgrade(alembic_config(conn), "base")
    assert set(inspect(engine).get_table_names()) <= {"alembic_version"}
    init_db(engine)
    assert TABLES <= set(inspect(engine).get_table_names())


def test_concurrent_init_db(db_settings: Settings) -> None:
    """api and worker start together: both migrate, neither fails."""
    errors: list[BaseException] = []
    barrier = threading.Barrier(3)

    def run() -> None:
        engine = make_engine(db_settings)
        try:
            barrier.wait()
            init_db(engine)
        except BaseException as exc:  # reported below
            errors.append(exc)
        finally:
            engine.dispose()

    threads = [threading.Thread(target=run) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []


def test_session_objects_survive_commit(session_factory: sessionmaker[Session]) -> None:
    from storage.models import Sequence

    with session_factory() as s:
        seq = Sequence(name="a", path="p")
        s.add(seq)
        s.commit()
    assert seq.name == "a" and len(seq.id) == 32  # expire_on_commit=False


def test_migrations_dir_is_inside_package() -> None:
    cfg = alembic_config()
    loc = Path(cfg.get_main_option("script_location") or "")
    assert loc.name == "migrations" and loc.parent.name == "storage" and (loc / "env.py").is_file()


def test_session_factory_binds_engine(engine: Engine) -> None:
    assert make_session_factory(engine)().get_bind() is engine


def test_0005_gives_each_archive_to_its_oldest_upload(engine: Engine) -> None:
    """Copies already added with allow_duplicate keep no claim, so the unique index can be built."""
    with engine.begin() as conn:
        command.downgrade(alembic_config(conn), "0004_sequence_content_hash")
        for sid, sha, created in [("b", "x" * 64, "2026-01-02"), ("a", "x" * 64, "2026-01-01"),
                                  ("c", "y" * 64, "2026-01-01"), ("d", None, "2026-01-01")]:
            conn.execute(
                text("INSERT INTO sequences (id, name, path, frames, duration_s, has_groundtruth, camera,"
                     " created_at, size_bytes, meta, content_sha256) VALUES (:id, :id, :id, 0, 0, false,"
                     " '{}', :created, 0, '{}', :sha)"),
                {"id": sid, "sha": sha, "created": created},
            )
    init_db(engine)
    with engine.connect() as conn:
        rows = conn.execute(text("SELECT id, claimed_sha256 FROM sequences ORDER BY id")).all()
    assert [tuple(r) for r in rows] == [("a", "x" * 64), ("b", None), ("c", "y" * 64), ("d", None)]
