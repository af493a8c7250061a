import json

from typer.testing import CliRunner

from cli.main import app
from worker.slam.errors import SlamError


def test_inspect_redkitchen(redkitchen):
    out = CliRunner().invoke(app, ["inspect", str(redkitchen), "--camera", "7scenes", "--json"])
    assert out.exit_code == 0, out.output
    report = json.loads(out.stdout)
    assert report["frames"] == 1000 and report["gt_coverage"] == 1.0
    assert 0.7 < report["depth_valid"] < 1.0 and report["camera"].startswith("7scenes")


def test_help_for_every_command():
    runner = CliRunner()
    for cmd in app.registered_commands:
        name = cmd.name or cmd.callback.__name__
        res = runner.invoke(app, [name, "--help"])
        assert res.exit_code == 0 and "Usage" in res.output, name


def test_inspect_names_a_repeated_timestamp(tmp_path):
    """Issue 60.6: the shared list reader refuses equal timestamps for the CLI as for the api."""
    from tests.backend.api.data import write_sequence

    folder = write_sequence(tmp_path / "seq", n=4)
    lines = (folder / "depth.txt").read_text().splitlines()
    lines[2] = f"{lines[1].split()[0]} {lines[2].split()[1]}"
    (folder / "depth.txt").write_text("\n".join(lines) + "\n")
    out = CliRunner().invoke(app, ["inspect", str(folder), "--json"])
    assert out.exit_code != 0 and isinstance(out.exception, SlamError)  # `vtdslam` maps it to exit code 2
    assert "depth.txt:3:" in str(out.exception) and "strictly increase" in str(out.exception)
