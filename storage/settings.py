"""Deployment settings (paths, URLs, tokens, limits), read from ``VTD_*`` environment variables.

Built by :func:`get_settings`, never at import time, so tests and processes each get their own.
"""

from __future__ import annotations

import hashlib
import hmac
from pathlib import Path
from typing import Any

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

GIB = 1024**3


class Settings(BaseSettings):
    """One process's deployment configuration; the embedded default needs none of it set."""

    model_config = SettingsConfigDict(env_prefix="VTD_", extra="forbid")

    data_dir: Path = Path("data")
    """Local data directory: SQLite database, queue file, sequences, artifacts, upload staging."""
    database_url: str | None = None
    """SQLAlchemy URL; None means SQLite in ``data_dir``. ``postgresql://…`` when scaled out."""
    queue_url: str | None = None
    """None means a huey SQLite file in ``data_dir``; ``redis://…`` when scaled out."""
    api_token: str | None = Field(default=None, repr=False)
    """Bearer token the api requires when set (kept out of repr so it never lands in logs)."""
    shared_dir: Path = Path("../shared")
    """Read-only real data (datasets, weights) shared between checkouts."""
    import_root: Path | None = None
    """Server folder below which sequences may be registered in place; None disables it."""
    cors_origins: list[str] = []
    """Browser origins (``https://host:port``, or ``*``) allowed to call the api cross-origin; empty (the
    default) sends no CORS headers, so only pages served by the api itself can use it from a browser.
    From the environment as JSON: ``VTD_CORS_ORIGINS='["https://dash.example"]'``."""

    max_upload_bytes: int = Field(default=4 * GIB, gt=0)
    max_files: int = Field(default=200_000, gt=0)
    max_ratio: float = Field(default=200.0, gt=0)
    """Largest unpacked/packed size ratio accepted for an archive (zip-bomb guard)."""
    upload_max_seconds: float = Field(default=3600.0, gt=0)
    """Longest an upload's body may take to arrive (``VTD_UPLOAD_MAX_SECONDS``); beyond, a 408 and nothing
    is stored. Bounds a client that trickles bytes just fast enough to dodge the idle timeout (4 GiB in an
    hour needs about 1.2 MB/s)."""

    db_pool_size: int = Field(default=10, ge=1, le=1000)
    db_max_overflow: int = Field(default=30, ge=0, le=1000)
    """Connections a process may open beyond ``db_pool_size`` under load. The api runs its sync handlers
    on anyio's thread pool (40 threads) and each holds one session for its duration, so 10 + 30 lets
    every thread get a connection without waiting; event streams hold none while they wait. N api
    processes need N x 40 of the database's ``max_connections`` (PostgreSQL's default is 100)."""
    max_streams_per_client: int = Field(default=16, ge=1, le=10_000)
    """Open ``GET /jobs/{id}/events`` streams one client address may hold (429 beyond)."""

    host: str = "127.0.0.1"
    """Address every server of the service binds: the api, the viewer hub and its per-run viser servers
    (the latter on loopback when ``api_token`` is set: browsers reach them through the api's ``/viewer/``)."""
    port: int = Field(default=8000, ge=1, le=65535)
    """The api's port: the only one a browser needs (the viewer is proxied under ``/viewer/{job_id}/``)."""
    viewer_port: int = Field(default=8080, ge=1, le=65535)
    """The viewer hub's control port, used by the api only."""
    heartbeat_timeout_s: float = Field(default=120.0, gt=0)
    """A running job whose worker has not reported for this long is failed (workers check every 1/4 of it)."""
    requeue_orphans: int = Field(default=0, ge=0)
    """How often a job whose worker died (orphaned or stale) is requeued automatically before it is failed;
    at most once whatever the setting: a job whose worker died twice is failed as a poison job."""

    def __repr_args__(self) -> Any:
        # URLs keep their shape in logs and reprs, never their passwords
        for name, value in super().__repr_args__():
            yield name, mask_url(value) if name in _URL_FIELDS and isinstance(value, str) else value

    @property
    def viewer_hub_key(self) -> str | None:
        """The secret the api sends the viewer hub when ``api_token`` is set (None: the hub asks for none).

        Derived from the token (HMAC-SHA256), so both processes share it without another setting and the
        token itself never travels to the hub."""
        if not self.api_token:
            return None
        return hmac.new(self.api_token.encode(), b"vtdslam viewer hub", hashlib.sha256).hexdigest()

    @property
    def resolved_database_url(self) -> str:
        """The database URL to connect to: ``database_url`` or SQLite in ``data_dir``."""
        if self.database_url:
            return self.database_url
        return f"sqlite:///{self.data_dir / 'vtdslam.db'}"

    @property
    def queue_path(self) -> Path:
        """The huey SQLite file used when no ``queue_url`` is set."""
        return self.data_dir / "queue.db"


_URL_FIELDS = ("database_url", "queue_url")


def mask_url(url: str) -> str:
    """``url`` with the password of its ``user:password@`` part replaced by ``***``.

    Up to the *last* '@': raw passwords may hold '@' or '/'; masking too much is harmless, too little is not.
    """
    scheme, sep, rest = url.partition("://")
    userinfo, at, tail = rest.rpartition("@")
    if not sep or not at or ":" not in userinfo:
        return url
    return f"{scheme}://{userinfo.split(':', 1)[0]}:***@{tail}"


def get_settings(**overrides: Any) -> Settings:
    """Settings from the environment; keyword ``overrides`` win over it (tests, CLI flags)."""
    return Settings(**overrides)
