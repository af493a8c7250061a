"""Fixtures for storage tests: settings in a temp data dir, migrated engines and sessions.

Database fixtures run on SQLite and, when reachable, on PostgreSQL (each test in its own schema).
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from storage.db import init_db, make_engine, make_session_factory
from storage.models import Sequence
from storage.repositories import sequences
from storage.settings import Settings, get_settings

PG_URL = os.environ.get("VTD_TEST_POSTGRES_URL", "postgresql://postgres@127.0.0.1:5432/test")
REDIS_URL = os.environ.get("VTD_TEST_REDIS_URL", "redis://127.0.0.1:6379/15")


@pytest.fixture(autouse=True)
def _no_vtd_env(no_vtd_env: None) -> None:
    """Every test here runs without a developer's VTD_* variables (tests/conftest.py)."""


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return get_settings(data_dir=tmp_path / "data")


@pytest.fixture(scope="session")
def postgres_url() -> str:
    import psycopg

    try:
        psycopg.connect(PG_URL, connect_timeout=3).close()
    except Exception as exc:  # any failure means: no usable server here
        pytest.skip(f"PostgreSQL not reachable at {PG_URL}: {exc}")
    return PG_URL


@pytest.fixture
def pg_settings(postgres_url: str, tmp_path: Path) -> Iterator[Settings]:
    """Settings pointing at a fresh schema (via search_path), dropped afterwards."""
    import psycopg

    schema = f"vtd_test_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgres_url, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    try:
        yield get_settings(
            data_dir=tmp_path / "data",
            database_url=f"{postgres_url}?options=-csearch_path%3D{schema}",
        )
    finally:
        with psycopg.connect(postgres_url, autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA "{schema}" CASCADE')


@pytest.fixture(scope="session")
def redis_url() -> str:
    import redis

    try:
        redis.Redis.from_url(REDIS_URL, socket_connect_timeout=3).ping()
    except Exception as exc:
        pytest.skip(f"Redis not reachable at {REDIS_URL}: {exc}")
    return REDIS_URL


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def db_settings(request: pytest.FixtureRequest, settings: Settings) -> Settings:
    """The settings of one database backend; tests using it run once per backend."""
    if request.param == "postgres":
        return request.getfixturevalue("pg_settings")
    return settings


@pytest.fixture
def engine(db_settings: Settings) -> Iterator[Engine]:
    eng = make_engine(db_settings)
    init_db(eng)
    yield eng
    eng.dispose()  # before the schema is dropped: open connections would block DROP SCHEMA


@pytest.fixture
def session_factory(engine: Engine) -> sessionmaker[Session]:
    return make_session_factory(engine)


@pytest.fixture
def session(session_factory: sessionmaker[Session]) -> Iterator[Session]:
    with session_factory() as s:
        yield s


@pytest.fixture
def make_sequence(session: Session) -> Callable[..., Sequence]:
    """Create a sequence row with sensible defaults."""

    def make(name: str = "seq", **kw: object) -> Sequence:
        kw.setdefault("path", f"sequences/{name}")
        return sequences.create(session, name=name, **kw)  # type: ignore[arg-type]

    return make
