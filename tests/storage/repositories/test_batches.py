from collections.abc import Callable

import pytest
from sqlalchemy.orm import Session

from storage.errors import InvalidInput, NotFound
from storage.models import JobStatus, Sequence
from storage.repositories import batches, jobs, metrics, sequences

PRESETS = ["orb-only", "no-restoration", "full"]


@pytest.fixture
def two(make_sequence: Callable[..., Sequence]) -> list[Sequence]:
    return [make_sequence("walking_xyz"), make_sequence("sitting_static")]


def test_create_makes_one_job_per_cell(session: Session, two: list[Sequence]) -> None:
    ids = [s.id for s in two]
    batch = batches.create(session, sequence_ids=ids + ids[:1], presets=PRESETS, name="ablation", config={"x": 1})
    got = batches.get(session, batch.id)
    assert (got.name, got.sequence_ids, got.presets) == ("ablation", ids, PRESETS)  # duplicates dropped
    cells = [(j.sequence_id, j.preset) for j in batches.jobs_of(session, batch.id)]
    assert cells == [(s, p) for s in ids for p in PRESETS]
    assert all(j.batch_id == batch.id and j.config == {"x": 1} for j in batches.jobs_of(session, batch.id))
    assert jobs.count(session, batch_id=batch.id) == 6


def test_create_validates(session: Session, two: list[Sequence]) -> None:
    with pytest.raises(NotFound) as ei:
        batches.create(session, sequence_ids=[two[0].id, "ghost"], presets=PRESETS)
    assert ei.value.detail == {"missing": ["ghost"]}
    with pytest.raises(InvalidInput):
        batches.create(session, sequence_ids=[], presets=PRESETS)
    with pytest.raises(InvalidInput):
        batches.create(session, sequence_ids=[two[0].id], presets=[""])
    assert jobs.count(session) == 0 and batches.list_batches(session) == []


def test_get_and_jobs_of_missing(session: Session) -> None:
    with pytest.raises(NotFound):
        batches.get(session, "missing")
    with pytest.raises(NotFound):
        batches.jobs_of(session, "missing")
    with pytest.raises(NotFound):
        batches.comparison(session, "missing")


def test_list_batches(session: Session, two: list[Sequence]) -> None:
    b1 = batches.create(session, sequence_ids=[two[0].id], presets=["full"])
    b2 = batches.create(session, sequence_ids=[two[1].id], presets=["full"])
    assert [b.id for b in batches.list_batches(session)] == [b2.id, b1.id]
    assert [b.id for b in batches.list_batches(session, limit=1, offset=1)] == [b1.id]


def test_comparison_rows(session: Session, two: list[Sequence]) -> None:
    batch = batches.create(session, sequence_ids=[s.id for s in two], presets=PRESETS)
    js = batches.jobs_of(session, batch.id)
    # walking × orb-only finished with metrics; walking × full failed; the rest are queued.
    assert jobs.claim(session, js[0].id, "w")
    metrics.save_run_metrics(
        session, js[0].id, {"ate": {"rmse": 0.5}, "rpe": {"trans_rmse": 0.1, "rot_rmse": 2.0}, "fps": 12.0}
    )
    jobs.finish(session, js[0].id, "succeeded")
    jobs.finish(session, js[2].id, "failed", error="x")

    rows = batches.comparison(session, batch.id)
    assert [(r.sequence_name, r.preset) for r in rows] == [(s.name, p) for s in two for p in PRESETS]
    first = rows[0].as_dict()
    assert first == {
        "sequence_id": two[0].id,
        "sequence_name": "walking_xyz",
        "preset": "orb-only",
        "job_id": js[0].id,
        "status": "succeeded",
        "ate_rmse": 0.5,
        "rpe_trans_rmse": 0.1,
        "rpe_rot_rmse": 2.0,
        "fps": 12.0,
        # no relocalisation count and no truth scores in this run's metrics
        "relocalisations": None,
        "mask_iou": None,
        "feature_precision": None,
        "feature_recall": None,
        "restoration_psnr": None,
        # a run made before the ground-truth frame was recorded: no frame, labels or per-frame RPE
        "groundtruth_frame": None,
        "ate_against": None,
        "ate_corrected_rmse": None,
        "ate_corrected_against": None,
        "rpe_against": None,
        "rpe_frame_trans_rmse": None,
        "rpe_frame_rot_rmse": None,
    }
    assert (rows[2].status, rows[2].ate_rmse) == ("failed", None)
    assert {r.status for r in rows[3:]} == {JobStatus.QUEUED.value}


def test_comparison_keeps_cells_of_deleted_sequence(session: Session, two: list[Sequence]) -> None:
    batch = batches.create(session, sequence_ids=[s.id for s in two], presets=["full"])
    sequences.delete(session, two[0].id)
    rows = batches.comparison(session, batch.id)
    assert [(r.sequence_id, r.sequence_name, r.job_id, r.status) for r in rows][0] == (two[0].id, None, None, None)
    assert rows[1].status == "queued"


def test_csv_headers_carry_units() -> None:
    from storage.repositories.batches import csv_header

    got = [csv_header(c) for c in ("sequence_id", "ate_rmse", "rpe_trans_rmse", "rpe_rot_rmse", "fps", "mask_iou",
                                   "restoration_psnr", "ate_corrected_rmse", "rpe_frame_trans_rmse",
                                   "rpe_frame_rot_rmse", "ate_against", "rpe_against", "groundtruth_frame")]
    assert got == ["sequence_id", "ate_rmse_m", "rpe_trans_rmse_m", "rpe_rot_rmse_deg", "fps", "mask_iou",
                   "restoration_psnr_db", "ate_corrected_rmse_m", "rpe_frame_trans_rmse_m", "rpe_frame_rot_rmse_deg",
                   "ate_against", "rpe_against", "groundtruth_frame"]
