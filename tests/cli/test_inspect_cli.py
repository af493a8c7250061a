import json

from typer.testing import CliRunner

from cli.main import app


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
