"""`vtdslam` entry point. Each subcommand lives in its own module and imports its heavy parts lazily."""
from __future__ import annotations

import sys

import typer

from cli import (
    augment_cmd,
    demo_cmd,
    eval_cmd,
    fetch_cmd,
    import_bag_cmd,
    inspect_cmd,
    msnet_cmd,
    run_cmd,
    serve_cmd,
    stream_cmd,
    synth_cmd,
    viewer_cmd,
    vocab_cmd,
    worker_cmd,
)

app = typer.Typer(
    name="vtdslam",
    help="VTD-SLAM: dynamic-scene RGB-D SLAM service, pipeline and tools.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _print_version(value: bool) -> None:
    if value:
        from formats.version import describe

        typer.echo(f"vtdslam {describe()}")
        raise typer.Exit()


@app.callback()
def _options(
    version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                 help="Print the package version (and the git commit in a checkout) and exit."),
) -> None:
    """VTD-SLAM: dynamic-scene RGB-D SLAM service, pipeline and tools."""


for module in (augment_cmd, demo_cmd, eval_cmd, fetch_cmd, import_bag_cmd, inspect_cmd, msnet_cmd, run_cmd, serve_cmd,
               stream_cmd, synth_cmd, viewer_cmd, vocab_cmd, worker_cmd):
    module.register(app)


def main() -> None:
    """Run the CLI; domain errors become a one-line message and exit code 2 (bad input) instead of a trace."""
    from cli.errors import run_with_error_mapping

    sys.exit(run_with_error_mapping(app))


if __name__ == "__main__":
    main()
