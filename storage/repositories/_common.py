"""Helpers shared by the repositories: transactions, lookups, paging."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TypeVar

from sqlalchemy.orm import Session

from storage.errors import InsufficientStorage, InvalidInput, NotFound
from storage.faults import disk_full, insufficient_storage
from storage.models import Base

M = TypeVar("M", bound=Base)

MAX_LIMIT = 1000


@contextmanager
def writing(session: Session) -> Iterator[None]:
    """Commit what the block did, or roll it back and re-raise."""
    try:
        yield
        session.commit()
    except BaseException as exc:
        session.rollback()
        if not isinstance(exc, InsufficientStorage) and disk_full(exc):  # a 507, not an unexpected error
            raise insufficient_storage("writing to the database") from exc
        raise


def get_or_raise(session: Session, model: type[M], key: str, label: str) -> M:
    """The row with primary key ``key``, re-read from the database, or :class:`NotFound`."""
    obj = session.get(model, key, populate_existing=True)
    if obj is None:
        raise NotFound(f"{label} {key} not found", {"id": key})
    return obj


def check_page(limit: int, offset: int) -> None:
    if not 1 <= limit <= MAX_LIMIT:
        raise InvalidInput(f"limit must be between 1 and {MAX_LIMIT}", {"limit": limit})
    if offset < 0:
        raise InvalidInput("offset must be >= 0", {"offset": offset})
