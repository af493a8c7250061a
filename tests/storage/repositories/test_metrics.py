import math

import pytest
from sqlalchemy.orm import Session

from storage.errors import Conflict, InvalidInput, NotFound
from storage.models import Job
from storage.repositories import jobs, metrics, sequences

BLOB = {
    "frames": 3,
    "fps": 10.5,
    "timings_ms": {"segmentation": 30.0},
    "ate": {"rmse": 0.02, "mean": 0.018, "median": 0.017, "std": 0.005, "max": 0.04},
    "rpe": {"trans": {"rmse": 0.011}, "rot": {"rmse": 0.3}},
    "tracked": 3,
    "lost": 0,
}


@pytest.fixture
def job(session: Session) -> Job:
    seq = sequences.create(session, name="s", path="p")
    return jobs.create(session, sequence_id=seq.id, preset="full")


def test_save_and_get(session: Session, job: Job) -> None:
    metrics.save_run_metrics(session, job.id, BLOB)
    row = metrics.get_run_metrics(session, job.id)
    assert (row.ate_rmse, row.ate_mean, row.ate_median, row.ate_std, row.ate_max) == (0.02, 0.018, 0.017, 0.005, 0.04)
    assert (row.rpe_trans_rmse, row.rpe_rot_rmse, row.fps, row.tracked, row.lost) == (0.011, 0.3, 10.5, 3, 0)
    assert row.metrics == BLOB
    assert jobs.get(session, job.id).metrics is not None  # the job carries them


def test_save_replaces(session: Session, job: Job) -> None:
    metrics.save_run_metrics(session, job.id, BLOB)
    metrics.save_run_metrics(session, job.id, {"fps": 1.0, "ate": {"rmse": float("nan")}})
    row = metrics.get_run_metrics(session, job.id)
    assert (row.fps, row.ate_rmse, row.ate_mean) == (1.0, None, None)
    assert row.metrics == {"fps": 1.0, "ate": {"rmse": None}}  # NaN is not JSON on PostgreSQL


def test_summary_columns_flat_rpe_and_garbage() -> None:
    cols = metrics.summary_columns({"rpe": {"trans_rmse": 1, "rot_rmse": "2"}, "ate": "n/a", "fps": math.inf})
    assert (cols["rpe_trans_rmse"], cols["rpe_rot_rmse"], cols["ate_rmse"], cols["fps"]) == (1.0, 2.0, None, None)


def test_json_safe_handles_numpy_like_values() -> None:
    class Scalar:
        def tolist(self) -> float:
            return 1.5

    assert metrics.json_safe({"a": (Scalar(), float("-inf")), 3: [1, "x"]}) == {"a": [1.5, None], "3": [1, "x"]}


def test_missing(session: Session) -> None:
    with pytest.raises(NotFound):
        metrics.get_run_metrics(session, "missing")
    with pytest.raises(NotFound):
        metrics.save_run_metrics(session, "missing", BLOB)
    with pytest.raises(NotFound):
        metrics.add_frame_stats(session, "missing", [{"frame_index": 0, "timestamp": 0.0}])


def test_frame_stats_bulk_in_chunks(session: Session, job: Job) -> None:
    rows = [
        {"frame_index": i, "timestamp": 0.1 * i, "tracked": i != 2, "n_features": 100 + i, "n_dynamic_removed": i,
         "ate_error": 0.01 * i if i else None, "timings": {"seg": 1.0}}
        for i in range(5)
    ]
    assert metrics.add_frame_stats(session, job.id, rows[:3]) == 3
    assert metrics.add_frame_stats(session, job.id, iter(rows[3:])) == 2
    assert metrics.add_frame_stats(session, job.id, []) == 0
    got = metrics.get_frame_stats(session, job.id)
    assert [f.frame_index for f in got] == list(range(5))
    assert (got[2].tracked, got[2].n_features, got[2].n_dynamic_removed, got[0].ate_error) == (False, 102, 2, None)
    assert got[4].timings == {"seg": 1.0}
    assert [f.frame_index for f in metrics.get_frame_stats(session, job.id, limit=2, offset=1)] == [1, 2]


def test_frame_stats_defaults_and_validation(session: Session, job: Job) -> None:
    metrics.add_frame_stats(session, job.id, [{"frame_index": 0, "timestamp": 1.0, "ate_error": float("nan")}])
    f = metrics.get_frame_stats(session, job.id)[0]
    assert (f.tracked, f.n_features, f.n_dynamic_removed, f.ate_error, f.timings) == (True, 0, 0, None, {})
    with pytest.raises(Conflict):
        metrics.add_frame_stats(session, job.id, [{"frame_index": 0, "timestamp": 1.0}])
    with pytest.raises(InvalidInput):
        metrics.add_frame_stats(session, job.id, [{"timestamp": 1.0}])
    assert len(metrics.get_frame_stats(session, job.id)) == 1  # the session still works
