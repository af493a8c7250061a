"""Where domain errors become exit codes: 0 ok, 1 unexpected failure, 2 bad input or usage."""
from __future__ import annotations

import typer

from formats.errors import VtdError

EXIT_BAD_INPUT = 2


def run_with_error_mapping(app: typer.Typer) -> int:
    try:
        app(standalone_mode=False)
    except VtdError as exc:  # the one root of storage's, the pipeline's and formats' errors
        typer.secho(f"error: {exc}", fg=typer.colors.RED, err=True)
        return EXIT_BAD_INPUT
    except typer.Abort:
        typer.secho("aborted", err=True)
        return 1
    except typer.Exit as exc:
        return exc.exit_code
    except Exception as exc:  # click usage errors carry their own exit code
        import click

        # typer >= 0.29 raises its vendored click's exceptions (`typer._click`); older typer, click's own
        if isinstance(exc, (click.ClickException, typer.TyperException)) and hasattr(exc, "show"):
            exc.show()
            return getattr(exc, "exit_code", EXIT_BAD_INPUT)
        raise
    return 0
