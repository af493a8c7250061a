"""One exception root: storage's, the pipeline's and formats' errors all derive from formats.errors.VtdError,
keeping their codes (and, for the service's, their HTTP statuses)."""
from __future__ import annotations

from backend.api.errors import ApiError
from formats.errors import FormatError, SpecError, VtdError
from storage import errors as storage_errors
from worker.slam import errors as slam_errors


def test_every_error_tree_hangs_under_the_root_with_its_code() -> None:
    codes = {
        storage_errors.NotFound: ("not_found", 404), storage_errors.InvalidInput: ("invalid_input", 422),
        storage_errors.Conflict: ("conflict", 409), storage_errors.ConfigurationError: ("configuration_error", 500),
        ApiError: ("api_error", 503),
    }
    for cls, (code, status) in codes.items():
        err = cls("m", {"k": 1})
        assert isinstance(err, VtdError) and (err.code, err.http_status) == (code, status)
        assert (err.message, err.detail, str(err)) == ("m", {"k": 1}, "m")
    for slam_cls, code in ((slam_errors.ConfigError, "invalid_config"), (slam_errors.CameraError, "invalid_camera"),
                           (slam_errors.EvaluationError, "evaluation_failed")):
        slam_err = slam_cls("m")
        assert isinstance(slam_err, VtdError) and slam_err.code == code and slam_err.detail == {}
    seq = slam_errors.SequenceFormatError("bad", path="a.txt", line=3)
    assert isinstance(seq, VtdError) and str(seq) == "a.txt:3: bad" and seq.detail == {"path": "a.txt", "line": 3}


def test_formats_errors() -> None:
    err = FormatError("bad line", path="rgb.txt", line=2)
    assert isinstance(err, VtdError) and isinstance(err, ValueError)
    assert (str(err), err.message, err.line) == ("rgb.txt:2: bad line", "bad line", 2)
    assert SpecError("x", {"field": "f"}).code == "invalid_input"
