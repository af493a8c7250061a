"""Batches: sequences x presets in one request (the paper's ablation in one click), status, comparison table."""

from __future__ import annotations

import csv
import io
from typing import Annotated, Literal

from fastapi import APIRouter, Query, status
from fastapi.responses import Response

from backend.api.deps import Auth, EnqueueDep, Limit, Offset, SessionDep
from backend.api.errors import error_responses
from backend.api.guard import GuardedRoute
from backend.api.jobs import check_config, enqueue_or_fail
from backend.api.schemas import BatchCreate, BatchId, BatchOut, Page, TableRow
from backend.api.stale import ReapStale
from storage.presets import check_preset
from storage.repositories import batches

router = APIRouter(prefix="/batches", tags=["batches"], route_class=GuardedRoute)

TABLE_COLUMNS = list(TableRow.model_fields)
CSV_COLUMNS = [batches.csv_header(c) for c in TABLE_COLUMNS]
"""The CSV's header: the JSON table's keys with their units (ate_rmse_m, rpe_rot_rmse_deg, ...)."""


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=BatchOut,
    dependencies=[Auth],
    responses=error_responses(400, 401, 404, 413, 422, 503, 507),
)
def create_batch(body: BatchCreate, session: SessionDep, enqueue: EnqueueDep) -> BatchOut:
    """One job per sequence x preset, all queued."""
    presets = [check_preset(p) for p in body.presets]
    batch = batches.create(
        session, sequence_ids=body.sequence_ids, presets=presets, name=body.name, config=check_config(body.config)
    )
    enqueue_or_fail(session, enqueue, [j.id for j in batches.jobs_of(session, batch.id)])
    return BatchOut.of(batch, batches.jobs_of(session, batch.id))


@router.get("", response_model=Page[BatchOut], dependencies=[ReapStale], responses=error_responses(422))
def list_batches(
    session: SessionDep,
    limit: Limit = 50,
    offset: Offset = 0,
) -> Page[BatchOut]:
    items = batches.list_batches(session, limit=limit, offset=offset)
    out = [BatchOut.of(b, batches.jobs_of(session, b.id)) for b in items]
    return Page[BatchOut](items=out, total=None, limit=limit, offset=offset)


@router.get("/{batch_id}", response_model=BatchOut, dependencies=[ReapStale], responses=error_responses(404))
def get_batch(batch_id: BatchId, session: SessionDep) -> BatchOut:
    return BatchOut.of(batches.get(session, batch_id), batches.jobs_of(session, batch_id))


@router.get(
    "/{batch_id}/table",
    response_model=list[TableRow],
    responses={
        200: {"content": {"text/csv": {"example": ",".join(CSV_COLUMNS) + "\n"}}},
        **error_responses(404, 422),
    },
)
def get_table(
    batch_id: BatchId,
    session: SessionDep,
    format: Annotated[Literal["json", "csv"], Query(description="json (default) or csv")] = "json",
) -> list[TableRow] | Response:
    """ATE RMSE (m), RPE translation (m) and rotation (deg) RMSE and fps per sequence and preset. The CSV's header
    names the units (ate_rmse_m, rpe_trans_rmse_m, rpe_rot_rmse_deg, restoration_psnr_db); the JSON keeps the keys."""
    rows = [TableRow.of(r) for r in batches.comparison(session, batch_id)]
    if format == "json":
        return rows
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for row in rows:
        cells = row.model_dump()
        writer.writerow(["" if cells[k] is None else cells[k] for k in TABLE_COLUMNS])
    return Response(
        buf.getvalue(),
        media_type="text/csv; charset=utf-8",
        headers={"Content-Disposition": f'attachment; filename="batch-{batch_id}.csv"'},
    )
