"""storage.faults.disk_full: a full disk however it is reported (issue 60.4)."""
from __future__ import annotations

import errno
import sqlite3

import pytest
from sqlalchemy.exc import IntegrityError, OperationalError

from storage.errors import InsufficientStorage, RequestTimeout, StorageError, Unreadable
from storage.faults import disk_full


def _wrapped(inner: BaseException) -> StorageError:
    try:
        try:
            raise inner
        except BaseException as exc:
            raise StorageError("could not record") from exc
    except StorageError as outer:
        return outer


@pytest.mark.parametrize("exc", [
    OSError(errno.ENOSPC, "No space left on device"),
    OSError(errno.EDQUOT, "Disk quota exceeded"),
    OperationalError("INSERT", {}, sqlite3.OperationalError("database or disk is full")),
    sqlite3.OperationalError("database or disk is full"),
    InsufficientStorage("full"),
    _wrapped(OSError(errno.ENOSPC, "No space left on device")),
])
def test_disk_full_is_recognised(exc: BaseException) -> None:
    assert disk_full(exc)


@pytest.mark.parametrize("exc", [
    OSError(errno.EACCES, "Permission denied"),
    OperationalError("INSERT", {}, sqlite3.OperationalError("database is locked")),
    IntegrityError("INSERT", {}, sqlite3.IntegrityError("UNIQUE constraint failed")),
    ValueError("full"),
])
def test_other_errors_are_not(exc: BaseException) -> None:
    assert not disk_full(exc)


def test_postgres_disk_full_by_sqlstate() -> None:
    errors = pytest.importorskip("psycopg.errors")
    assert disk_full(OperationalError("INSERT", {}, errors.DiskFull("could not extend file")))


@pytest.mark.parametrize(("cls", "status", "code"), [
    (InsufficientStorage, 507, "insufficient_storage"),
    (Unreadable, 500, "artifact_unreadable"),
    (RequestTimeout, 408, "request_timeout"),
])
def test_the_new_domain_errors(cls: type[StorageError], status: int, code: str) -> None:
    err = cls("boom", {"k": 1})
    assert isinstance(err, StorageError) and (err.http_status, err.code) == (status, code)
