"""Sequences: upload an archive (streamed to disk, validated, installed atomically), register a server
folder, list, get, thumbnail, delete."""

from __future__ import annotations

import mimetypes
import re
from pathlib import Path

import anyio
from fastapi import APIRouter, Request, Response, status
from fastapi.responses import FileResponse
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from backend.api.deps import Auth, Limit, Offset, SessionDep, SettingsDep, StoreDep
from backend.api.errors import error_responses
from backend.api.files import serve_file
from backend.api.guard import GuardedRoute
from backend.api.schemas import Page, SequenceId, SequenceImport, SequenceOut
from backend.api.upload import receive_upload
from storage.errors import InvalidInput, NotFound
from storage.ingest import ingest_staged, register_folder, upload_limits
from storage.ingest.archive import remove_tree
from storage.ingest.stream import ArchiveSink
from storage.presets import CAMERA_PRESETS, parse_camera_spec
from storage.repositories import sequences

router = APIRouter(prefix="/sequences", tags=["sequences"], route_class=GuardedRoute)

_UPLOAD_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["file", "camera"],
                    "properties": {
                        "file": {
                            "type": "string",
                            "format": "binary",
                            "description": ".zip or .tar.gz/.tgz of a TUM-layout folder (or of its contents); or a "
                            "ROS bag: a ROS 1 .bag, a ROS 2 .mcap or .db3 file, or a .zip/.tar.gz of a ROS 2 bag "
                            "folder (metadata.yaml beside its files), converted with its topics found automatically",
                        },
                        "camera": {
                            "type": "string",
                            "description": f"camera preset ({', '.join(CAMERA_PRESETS)}) or JSON intrinsics",
                            "examples": ["tum3", '{"fx":535.4,"fy":539.2,"cx":320.1,"cy":247.6}'],
                        },
                        "name": {"type": "string", "description": "display name (default: the file's)"},
                        "allow_duplicate": {
                            "type": "boolean",
                            "description": "add the archive even if the same file was uploaded before "
                            "(otherwise 409 naming that sequence)",
                            "default": False,
                        },
                    },
                }
            }
        },
    }
}
_ARCHIVE_SUFFIX = re.compile(r"(\.tar\.gz|\.tgz|\.zip|\.tar|\.bag|\.mcap|\.db3)$", re.IGNORECASE)


_TRUE, _FALSE = {"true", "1", "yes", "on"}, {"false", "0", "no", "off", ""}


def _flag(fields: dict[str, str], key: str) -> bool:
    value = fields.get(key, "").strip().lower()
    if value not in _TRUE | _FALSE:
        raise InvalidInput(f"form field {key!r} must be true or false", {key: value[:40]})
    return value in _TRUE


def _refuse_duplicate(session: Session, sha256: str) -> None:
    """A :class:`Conflict` naming the sequence this very archive already made, if there is one."""
    existing = sequences.find_by_content(session, sha256)
    if existing is not None:
        raise sequences.duplicate_upload(existing, sha256)


def _default_name(filename: str | None) -> str:
    base = Path(filename or "").name
    return _ARCHIVE_SUFFIX.sub("", base) or "sequence"


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=SequenceOut,
    dependencies=[Auth],
    openapi_extra=_UPLOAD_BODY,
    responses=error_responses(401, 408, 409, 413, 422, 507),
    summary="Upload a sequence archive",
)
async def upload_sequence(
    request: Request, session: SessionDep, store: StoreDep, settings: SettingsDep
) -> SequenceOut:
    """Stream the archive to disk, unpack it safely, validate the TUM layout and install it atomically.

    A ROS bag (ROS 1 ``.bag``; ROS 2 ``.mcap`` or ``.db3`` file, or an archive of a ROS 2 bag folder) is
    converted to that layout first (colour, depth and CameraInfo topics found automatically), under the same
    limits.

    Rejected uploads leave nothing behind (no files, no row); so do uploads the client abandons.
    The same archive (SHA-256 of its bytes) a second time is a 409 unless ``allow_duplicate`` is true.
    """
    staging = store.new_staging_dir()
    sink = ArchiveSink(staging, upload_limits(settings))
    try:
        form = await receive_upload(request, sink, file_field="file", max_bytes=settings.max_upload_bytes,
                                    max_seconds=settings.upload_max_seconds)
        await run_in_threadpool(sink.close)
        if "camera" not in form.fields:
            raise InvalidInput("the form needs a 'camera' field (a preset name or JSON intrinsics)")
        camera = parse_camera_spec(form.fields["camera"])
        name = (form.fields.get("name") or "").strip()[:255] or _default_name(form.filename)
        unique = not _flag(form.fields, "allow_duplicate")
        if unique:  # refused early here; the database refuses the one that raced past (same 409)
            await run_in_threadpool(_refuse_duplicate, session, form.sha256)
        with anyio.CancelScope(shield=True):  # once the body is in, finish even if the client leaves
            seq = await run_in_threadpool(
                ingest_staged, session, store, settings, staging,
                name=name, camera=camera, content_sha256=form.sha256, unique=unique,
            )
    except BaseException:
        with anyio.CancelScope(shield=True):  # a disconnect cancels the request: clean up regardless
            await run_in_threadpool(sink.abort)
        raise
    finally:
        with anyio.CancelScope(shield=True):
            await run_in_threadpool(remove_tree, staging)
    return SequenceOut.of(seq)


@router.post(
    "/import",
    status_code=status.HTTP_201_CREATED,
    response_model=SequenceOut,
    dependencies=[Auth],
    responses=error_responses(400, 401, 404, 413, 422),
    summary="Register a folder already on the server",
)
def import_sequence(
    body: SequenceImport, session: SessionDep, store: StoreDep, settings: SettingsDep
) -> SequenceOut:
    """The folder must lie below ``VTD_IMPORT_ROOT``; it is validated and used in place (not copied)."""
    camera = parse_camera_spec(body.camera)
    return SequenceOut.of(register_folder(session, store, settings, body.path, name=body.name, camera=camera))


@router.get("", response_model=Page[SequenceOut], responses=error_responses(422))
def list_sequences(
    session: SessionDep,
    limit: Limit = 50,
    offset: Offset = 0,
) -> Page[SequenceOut]:
    """Newest first."""
    items = sequences.list_sequences(session, limit=limit, offset=offset)
    latest = sequences.latest_jobs(session, [s.id for s in items])
    return Page[SequenceOut](
        items=[SequenceOut.of(s, latest.get(s.id)) for s in items],
        total=sequences.count(session),
        limit=limit,
        offset=offset,
    )


@router.get("/{sequence_id}", response_model=SequenceOut, responses=error_responses(404))
def get_sequence(sequence_id: SequenceId, session: SessionDep) -> SequenceOut:
    return SequenceOut.of(
        sequences.get(session, sequence_id), sequences.latest_jobs(session, [sequence_id]).get(sequence_id)
    )


@router.get(
    "/{sequence_id}/thumbnail",
    response_class=FileResponse,
    responses={200: {"content": {"image/png": {}, "image/jpeg": {}}}, **error_responses(404, 416, 500)},
)
def get_thumbnail(sequence_id: SequenceId, request: Request, session: SessionDep, store: StoreDep) -> FileResponse:
    """The first frame's colour image, as stored."""
    seq = sequences.get(session, sequence_id)
    rel = seq.meta.get("thumbnail")
    root = store.resolve(seq.path).resolve()
    path = (root / rel).resolve() if rel else None
    if path is None or not path.is_relative_to(root):  # serve_file: missing is 404, unreadable a clear 500
        raise NotFound(f"sequence {sequence_id} has no thumbnail", {"id": sequence_id})
    media = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
    return serve_file(path, request, media_type=media, what=f"sequence {sequence_id}'s thumbnail",
                      missing=NotFound(f"sequence {sequence_id} has no thumbnail", {"id": sequence_id}),
                      headers={"Cache-Control": "max-age=3600"})


@router.delete(
    "/{sequence_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    dependencies=[Auth],
    responses=error_responses(401, 404),
)
def delete_sequence(sequence_id: SequenceId, session: SessionDep, store: StoreDep) -> Response:
    """Delete the sequence, its jobs (running ones stop) and their artifacts.

    A folder registered in place is left untouched on the server; only uploaded files are removed.
    """
    job_ids = sequences.delete(session, sequence_id)
    for job_id in job_ids:
        store.delete_job(job_id)
    store.delete_sequence(sequence_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
