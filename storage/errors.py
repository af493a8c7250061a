"""The service's exception tree, under the project's root :class:`formats.errors.VtdError`.

The api maps ``http_status``/``code`` to ``{"error": {"code", "message", "detail"}}``, the worker turns
any of them into a failed job with ``message``, the CLI into an exit code.
"""

from __future__ import annotations

from typing import Any

from formats.errors import VtdError


class ServiceError(VtdError):
    """Anything the service answers with an error body: ``code``, ``http_status``, ``message`` and
    ``detail`` (optional JSON-able context for the client). Domain errors are :class:`StorageError`; the
    api's own (a dependency it fronts is down) live in ``backend``."""

    code: str = "error"
    http_status: int = 500

    def to_dict(self) -> dict[str, Any]:
        """The error body the api returns (under the ``"error"`` key)."""
        return {"code": self.code, "message": self.message, "detail": self.detail}


class StorageError(ServiceError):
    """Base of every domain error."""


class NotFound(StorageError):
    code = "not_found"
    http_status = 404


class Conflict(StorageError):
    """The resource's state forbids the operation (e.g. retrying a running job)."""

    code = "conflict"
    http_status = 409


class InvalidInput(StorageError):
    code = "invalid_input"
    http_status = 422


class PayloadTooLarge(StorageError):
    code = "payload_too_large"
    http_status = 413


class Unauthorized(StorageError):
    code = "unauthorized"
    http_status = 401


class ConfigurationError(StorageError):
    """The deployment settings are unusable (unknown URL scheme, …): the operator's fault."""

    code = "configuration_error"
    http_status = 500


class Unreadable(StorageError):
    """A stored file the service cannot read (an api and a worker under different users on shared storage,
    a restore with the wrong owner): the operator's fault, answered in words, never as a truncated file."""

    code = "artifact_unreadable"
    http_status = 500


class InsufficientStorage(StorageError):
    """The data dir's disk or the database is full: nothing was stored; free space and try again."""

    code = "insufficient_storage"
    http_status = 507


class RequestTimeout(StorageError):
    """A request took longer than the service allows (an upload that trickles in): nothing was stored."""

    code = "request_timeout"
    http_status = 408
