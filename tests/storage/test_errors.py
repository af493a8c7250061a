import pytest

from storage.errors import (
    ConfigurationError,
    Conflict,
    InvalidInput,
    NotFound,
    PayloadTooLarge,
    StorageError,
    Unauthorized,
)


@pytest.mark.parametrize(
    ("cls", "status", "code"),
    [
        (NotFound, 404, "not_found"),
        (Conflict, 409, "conflict"),
        (InvalidInput, 422, "invalid_input"),
        (PayloadTooLarge, 413, "payload_too_large"),
        (Unauthorized, 401, "unauthorized"),
        (ConfigurationError, 500, "configuration_error"),
    ],
)
def test_tree(cls: type[StorageError], status: int, code: str) -> None:
    err = cls("boom", {"k": 1})
    assert isinstance(err, StorageError)
    assert (err.http_status, err.code, err.message, err.detail, str(err)) == (status, code, "boom", {"k": 1}, "boom")
    assert err.to_dict() == {"code": code, "message": "boom", "detail": {"k": 1}}


def test_detail_defaults_to_none() -> None:
    assert NotFound("x").detail is None
