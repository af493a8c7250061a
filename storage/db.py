"""Engine, sessions and schema migration, all built from a :class:`Settings` (nothing at import)."""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sqlalchemy import Connection, Engine, create_engine, event, text
from sqlalchemy.engine import URL, make_url
from sqlalchemy.orm import Session, sessionmaker

from storage.errors import ConfigurationError
from storage.settings import Settings

BUSY_TIMEOUT_S = 30
POOL_TIMEOUT_S = 10
MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"
# Any constant: serialises concurrent migrations (api and worker starting together) on PostgreSQL.
_PG_MIGRATION_LOCK = 0x76746473


def normalize_url(url: str) -> URL:
    """Parse ``url``; a bare ``postgresql://``/``postgres://`` URL gets the psycopg 3 driver."""
    if url.startswith("postgres://"):  # Heroku-style alias SQLAlchemy does not accept
        url = "postgresql://" + url[len("postgres://") :]
    try:
        parsed = make_url(url)
    except Exception as exc:  # ArgumentError; the message names the bad URL's shape
        raise ConfigurationError(f"invalid database URL: {exc}") from exc
    if parsed.drivername == "postgresql":
        parsed = parsed.set(drivername="postgresql+psycopg")
    return parsed


def make_engine(settings: Settings, **kwargs: Any) -> Engine:
    """An engine for ``settings.resolved_database_url``; ``kwargs`` go to ``create_engine``."""
    url = normalize_url(settings.resolved_database_url)
    if url.get_backend_name() == "sqlite":
        if url.database and url.database != ":memory:":  # in-memory SQLite uses a single-connection pool
            _pool_kwargs(settings, kwargs)
        return _sqlite_engine(url, **kwargs)
    kwargs.setdefault("pool_pre_ping", True)  # long-lived workers outlive server-side idle timeouts
    _pool_kwargs(settings, kwargs)
    return create_engine(url, **kwargs)


def _pool_kwargs(settings: Settings, kwargs: dict[str, Any]) -> None:
    """Pool size from the settings (see ``Settings.db_max_overflow`` for the sizing); a request that
    still finds the pool empty waits ``POOL_TIMEOUT_S``, then fails, instead of hanging."""
    if kwargs.get("poolclass") is not None:
        return
    kwargs.setdefault("pool_size", settings.db_pool_size)
    kwargs.setdefault("max_overflow", settings.db_max_overflow)
    kwargs.setdefault("pool_timeout", POOL_TIMEOUT_S)


def _sqlite_engine(url: URL, **kwargs: Any) -> Engine:
    if url.database and url.database != ":memory:" and not url.database.startswith("file:"):
        Path(url.database).parent.mkdir(parents=True, exist_ok=True)
    connect_args = {"check_same_thread": False, "timeout": BUSY_TIMEOUT_S, **kwargs.pop("connect_args", {})}
    engine = create_engine(url, connect_args=connect_args, **kwargs)

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_conn: Any, _record: Any) -> None:
        # busy_timeout first so the WAL switch itself waits for other processes instead of failing.
        cur = dbapi_conn.cursor()
        cur.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_S * 1000}")
        _enable_wal(cur)  # readers (api) never block the writer (worker)
        cur.execute("PRAGMA synchronous = NORMAL")  # durable enough under WAL, much faster commits
        cur.execute("PRAGMA foreign_keys = ON")  # off by default in SQLite; cascades rely on it
        cur.close()

    return engine


def _enable_wal(cur: Any) -> None:
    """Switch the file to WAL (persistent, so a no-op after the first time).

    The first switch needs an exclusive lock and SQLite reports "locked" at once instead of calling
    the busy handler, so processes opening a new database together retry here.
    """
    deadline = time.monotonic() + BUSY_TIMEOUT_S
    while True:
        try:
            cur.execute("PRAGMA journal_mode = WAL")
            return
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() > deadline:
                raise
            time.sleep(0.02)


def make_session_factory(engine: Engine) -> sessionmaker[Session]:
    """Sessions whose objects stay readable after commit/close (the api serialises them afterwards)."""
    return sessionmaker(bind=engine, expire_on_commit=False)


def init_db(target: Settings | Engine) -> None:
    """Migrate the database to the newest Alembic revision; safe to call from several processes."""
    if isinstance(target, Settings):
        engine = make_engine(target)
        try:
            _upgrade(engine)
        finally:
            engine.dispose()
    else:
        _upgrade(target)


def alembic_config(connection: Any = None) -> Any:
    """An Alembic ``Config`` built in code (no alembic.ini), pointing at the packaged migrations."""
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    cfg.attributes["connection"] = connection
    return cfg


def _upgrade(engine: Engine) -> None:
    from alembic import command

    with engine.connect() as conn:
        # One transaction around the whole upgrade, taken before Alembic reads the version table, so a
        # second process waits and then finds the schema at head.
        if engine.dialect.name == "sqlite":
            _upgrade_sqlite(conn, lambda: command.upgrade(alembic_config(conn), "head"))
            return
        if engine.dialect.name == "postgresql":
            conn.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": _PG_MIGRATION_LOCK})
        command.upgrade(alembic_config(conn), "head")
        conn.commit()


def _upgrade_sqlite(conn: Connection, upgrade: Callable[[], None]) -> None:
    """SQLite's documented procedure for schema changes.

    Foreign keys off (batch migrations recreate tables, and dropping a parent table would fire
    ON DELETE CASCADE), one immediate transaction (pysqlite would run DDL outside any), an integrity
    check before commit, foreign keys back on before the connection returns to the pool.
    """
    conn.exec_driver_sql("PRAGMA foreign_keys = OFF")  # a no-op inside a transaction: do it first
    try:
        conn.exec_driver_sql("BEGIN IMMEDIATE")
        upgrade()
        broken = conn.exec_driver_sql("PRAGMA foreign_key_check").fetchall()
        if broken:
            raise RuntimeError(f"migration left broken foreign keys: {broken[:5]}")
        conn.commit()
    finally:
        try:
            conn.rollback()
            conn.exec_driver_sql("PRAGMA foreign_keys = ON")
            conn.commit()
        except Exception:
            conn.invalidate()  # never hand out a connection with foreign keys off
            raise
