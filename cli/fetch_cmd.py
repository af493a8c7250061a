"""`vtdslam fetch NAME [NAME ...] --to DIR`: the standard benchmarks by name (TUM RGB-D, Bonn RGB-D Dynamic)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("fetch")(fetch_command)


def fetch_command(
    names: Annotated[list[str] | None, typer.Argument(
        help="Sequences (see --list), their official folder names, or a bench table (tum-walking, bonn-crowd).",
        show_default=False)] = None,
    to: Annotated[Path | None, typer.Option("--to", help="Folder the sequences unpack into (created).")] = None,
    url_base: Annotated[str | None, typer.Option(
        help="Download from this address instead of the official sites (a mirror; the tests' local server).")]
    = None,
    retries: Annotated[int, typer.Option(min=0, help="Resume an interrupted transfer this many times.")] = 2,
    list_: Annotated[bool, typer.Option("--list", help="List the known sequences and tables, and exit.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
) -> None:
    """Download, verify (size, sha256 when known, the archive's own checksums, the TUM layout) and unpack each
    sequence into DIR/<official folder>, with camera.json for its camera. An interrupted download resumes on the
    next call; a damaged one is refused and nothing is unpacked; a sequence already there is skipped."""
    from cli.fetch.catalog import DATASETS, TABLES, lookup
    from cli.fetch.download import FetchError, fetch

    if list_:
        for d in DATASETS.values():
            typer.echo(f"{d.name:32s} {d.camera:5s} {d.url()}")
        for table, members in TABLES.items():
            typer.echo(f"table {table}: {' '.join(members)}")
        return
    if not names or to is None:
        raise typer.BadParameter("give sequence names and --to DIR (or --list)")
    chosen = []
    for name in names:
        if name in TABLES:
            chosen += [DATASETS[n] for n in TABLES[name]]
            continue
        try:
            chosen.append(lookup(name))
        except KeyError:
            raise FetchError(f"unknown sequence {name!r}; `vtdslam fetch --list` names them",
                             {"choices": sorted(DATASETS)}) from None
    to.mkdir(parents=True, exist_ok=True)
    failed: list[str] = []
    for ds in dict.fromkeys(chosen):  # one failure does not stop the others
        typer.echo(f"{ds.name}: {ds.url(url_base)}")
        try:
            done = fetch(ds, to, url_base=url_base, retries=retries, progress=not quiet)
        except FetchError as exc:
            typer.secho(f"{ds.name}: {exc}", fg=typer.colors.RED, err=True)
            failed.append(ds.name)
            continue
        what = {"present": "already present, skipped", "downloaded": "downloaded and unpacked",
                "resumed": "resumed, downloaded and unpacked"}[done.status]
        typer.echo(f"{ds.name}: {what} -> {done.folder}")
    if failed:
        raise FetchError(f"{len(failed)} of {len(dict.fromkeys(chosen))} not fetched: {', '.join(failed)} "
                         "(an interrupted download resumes when fetched again)", {"failed": failed})
