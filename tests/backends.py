"""Throwaway PostgreSQL schemas and Redis databases for tests of the scaled-out backends; a test that needs
one is skipped, with the reason, when its server does not answer."""
from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

PG_URL = os.environ.get("VTD_TEST_POSTGRES_URL", "postgresql://postgres@127.0.0.1:5432/test")
REDIS_BASE = os.environ.get("VTD_TEST_REDIS_BASE", "redis://127.0.0.1:6379")


def _require_postgres() -> None:
    psycopg = pytest.importorskip("psycopg")
    try:
        psycopg.connect(PG_URL, connect_timeout=3).close()
    except Exception as exc:  # any failure means: no usable server here
        pytest.skip(f"PostgreSQL not reachable at {PG_URL}: {exc}")


def _require_redis() -> None:
    redis = pytest.importorskip("redis")
    try:
        redis.Redis.from_url(REDIS_BASE, socket_connect_timeout=3).ping()
    except Exception as exc:
        pytest.skip(f"Redis not reachable at {REDIS_BASE}: {exc}")


@contextmanager
def pg_schema_url(prefix: str = "vtd_test_") -> Iterator[str]:
    """A database URL whose search_path is a fresh schema, dropped afterwards."""
    _require_postgres()
    import psycopg

    schema = f"{prefix}{uuid.uuid4().hex[:12]}"
    with psycopg.connect(PG_URL, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    try:
        yield f"{PG_URL}?options=-csearch_path%3D{schema}"
    finally:
        with psycopg.connect(PG_URL, autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA "{schema}" CASCADE')


@contextmanager
def redis_db_url() -> Iterator[str]:
    """An empty Redis database (1..14) claimed with a marker key, flushed afterwards: the queue's name is
    fixed, so a database nobody else uses is what isolates it."""
    _require_redis()
    import redis

    for i in range(1, 15):
        url = f"{REDIS_BASE}/{i}"
        r = redis.Redis.from_url(url)
        if r.dbsize() == 0 and r.set("vtd-test-owner", uuid.uuid4().hex, nx=True):
            break
    else:
        pytest.skip("no empty Redis database among 1..14")
    try:
        yield url
    finally:
        redis.Redis.from_url(url).flushdb()


@contextmanager
def scaled_urls(prefix: str = "vtd_test_") -> Iterator[tuple[str, str]]:
    """``(database URL, queue URL)``: a fresh PostgreSQL schema and an empty Redis database, both removed
    afterwards; skipped before either is made when one server does not answer."""
    _require_postgres()
    _require_redis()
    with pg_schema_url(prefix) as database_url, redis_db_url() as queue_url:
        yield database_url, queue_url
