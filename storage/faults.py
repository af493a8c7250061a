"""Recognising a full disk, whoever reports it: an ``OSError`` (ENOSPC, EDQUOT) from a write, SQLite's
"database or disk is full", PostgreSQL's SQLSTATE 53100 (``disk_full``), wrapped by SQLAlchemy or not.
Every writer turns it into :class:`storage.errors.InsufficientStorage` (a 507 at the api) instead of an
unexpected error."""

from __future__ import annotations

import errno

from storage.errors import InsufficientStorage

_ERRNOS = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)}
_SQLITE_FULL = "database or disk is full"
_PG_DISK_FULL = "53100"


def disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` (or what it wraps: ``orig``, ``__cause__``, ``__context__``) says the disk is full."""
    seen: set[int] = set()
    todo: list[BaseException | None] = [exc]
    while todo:
        e = todo.pop()
        if e is None or id(e) in seen or len(seen) > 16:
            continue
        seen.add(id(e))
        if isinstance(e, InsufficientStorage):
            return True
        if isinstance(e, OSError) and e.errno in _ERRNOS:
            return True
        if _PG_DISK_FULL in (getattr(e, "sqlstate", None), getattr(e, "pgcode", None)):
            return True
        if type(e).__name__ == "OperationalError" and _SQLITE_FULL in str(e):
            return True
        orig = getattr(e, "orig", None)  # SQLAlchemy's DBAPIError wraps the driver's error
        todo += [orig if isinstance(orig, BaseException) else None, e.__cause__, e.__context__]
    return False


def insufficient_storage(what: str) -> InsufficientStorage:
    return InsufficientStorage(f"the server is out of storage space while {what}; nothing was stored. "
                               "Free space on the server and try again", {"while": what})
