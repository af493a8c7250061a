"""`vtdslam --version`."""
from __future__ import annotations

from formats.version import describe, package_version


def test_version_cli_prints_the_version_and_exits() -> None:
    from typer.testing import CliRunner

    from cli.main import app

    out = CliRunner().invoke(app, ["--version"])
    assert out.exit_code == 0
    assert out.output.strip() == f"vtdslam {describe()}" and package_version() in out.output
