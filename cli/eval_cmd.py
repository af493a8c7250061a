"""`vtdslam eval GROUNDTRUTH ESTIMATE`: ATE and RPE of a TUM trajectory against ground truth."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("eval")(eval_command)


def eval_command(
    groundtruth: Annotated[Path, typer.Argument(help="Ground-truth TUM trajectory (t tx ty tz qx qy qz qw).")],
    estimate: Annotated[Path, typer.Argument(help="Estimated TUM trajectory.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the metrics as JSON.")] = False,
    max_diff: Annotated[float, typer.Option(help="Max timestamp difference for association (s).")] = 0.02,
    rpe_delta: Annotated[float, typer.Option(help="RPE interval in seconds.")] = 1.0,
) -> None:
    """ATE (SE(3)-aligned, no scale, as TUM evaluate_ate) and RPE per second (as TUM evaluate_rpe), via evo."""
    from worker.slam.evaluation.metrics import evaluate
    from worker.slam.io.trajectory import read_tum_trajectory

    result = evaluate(read_tum_trajectory(groundtruth), read_tum_trajectory(estimate), max_diff, rpe_delta)
    if as_json:
        typer.echo(json.dumps(result.to_dict(), indent=2))
        return
    typer.echo(f"matched poses        {result.matched}")
    a = result.ate
    typer.echo(f"ATE  (m)             rmse {a.rmse:.4f}  mean {a.mean:.4f}  median {a.median:.4f}  "
               f"std {a.std:.4f}  max {a.max:.4f}")
    if result.rpe_trans is not None and result.rpe_rot is not None:
        t, r = result.rpe_trans, result.rpe_rot
        typer.echo(f"RPE trans (m/{rpe_delta:g}s)   rmse {t.rmse:.4f}  mean {t.mean:.4f}  median {t.median:.4f}  "
                   f"max {t.max:.4f}")
        typer.echo(f"RPE rot (deg/{rpe_delta:g}s)   rmse {r.rmse:.3f}  mean {r.mean:.3f}  median {r.median:.3f}  "
                   f"max {r.max:.3f}")
    else:
        typer.echo(f"RPE                  n/a (trajectory shorter than {rpe_delta:g} s)")
