"""`vtdslam eval GROUNDTRUTH ESTIMATE`: ATE and RPE of a TUM trajectory against ground truth."""
from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

if TYPE_CHECKING:
    from worker.slam.evaluation.metrics import EvalResult

_RPE_MODES = ("all-pairs", "fixed-delta")


def register(app: typer.Typer) -> None:
    app.command("eval")(eval_command)


def eval_command(
    groundtruth: Annotated[Path, typer.Argument(help="Ground-truth TUM trajectory (t tx ty tz qx qy qz qw).")],
    estimate: Annotated[Path, typer.Argument(help="Estimated TUM trajectory.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the metrics as JSON.")] = False,
    max_diff: Annotated[float, typer.Option(help="Max timestamp difference for the ATE's association (s).")] = 0.02,
    rpe_mode: Annotated[str, typer.Option(
        help="RPE pairs, as TUM evaluate_rpe.py: 'all-pairs' (the script's default; every pair, i.e. its "
             "--max_pairs 0) or 'fixed-delta' (its --fixed_delta: each pose with the one --rpe-delta seconds "
             "later, the drift per interval that a run's metrics.json reports).")] = "all-pairs",
    rpe_delta: Annotated[float, typer.Option(help="RPE interval in seconds (fixed-delta mode).")] = 1.0,
    rpe_max_pairs: Annotated[int, typer.Option(
        help="Evaluate at most this many pose pairs, sampled with a fixed seed (the script's --max_pairs; its "
             "default 10000 makes its all-pairs figures random); 0 = every pair. All pairs of N poses hold N^2 "
             "errors: bound it for trajectories of many thousand poses.")] = 0,
    plot: Annotated[Path | None, typer.Option(
        "--plot", help="Also write figures (PNG) into this folder: the top view and x/y/z over time of the "
                       "estimate against the aligned ground truth, and the error per pose over time.")] = None,
) -> None:
    """ATE (SE(3)-aligned, no scale, as TUM evaluate_ate, via evo) and RPE as TUM evaluate_rpe."""
    from worker.slam.evaluation.metrics import RpeMode, evaluate
    from worker.slam.io.trajectory import read_tum_trajectory

    if rpe_mode not in _RPE_MODES:
        raise typer.BadParameter(f"must be one of {', '.join(_RPE_MODES)}", param_hint="--rpe-mode")
    if rpe_delta <= 0:
        raise typer.BadParameter("must be positive", param_hint="--rpe-delta")
    if rpe_max_pairs < 0:
        raise typer.BadParameter("must be 0 (every pair) or positive", param_hint="--rpe-max-pairs")
    est = read_tum_trajectory(estimate)
    result = evaluate(read_tum_trajectory(groundtruth), est, max_diff, rpe_delta, RpeMode(rpe_mode), rpe_max_pairs)
    if as_json:
        typer.echo(json.dumps(result.to_dict(), indent=2))
    else:
        _print(result, rpe_delta, rpe_max_pairs)
    if plot is not None:
        from worker.slam.evaluation.plots import write_figures

        written = write_figures(plot, est, result.aligned_groundtruth,
                                (result.matched_timestamps, result.ate_errors), title=estimate.stem)
        typer.echo(f"figures: {', '.join(str(p) for p in written)}", err=as_json)  # stdout stays JSON


def _print(result: EvalResult, rpe_delta: float, rpe_max_pairs: int) -> None:
    typer.echo(f"matched poses        {result.matched}")
    a = result.ate
    typer.echo(f"ATE  (m)             rmse {a.rmse:.4f}  mean {a.mean:.4f}  median {a.median:.4f}  "
               f"std {a.std:.4f}  max {a.max:.4f}")
    if result.rpe is None:
        typer.echo("RPE                  n/a (fewer than 2 pose pairs)")
        return
    t, r = result.rpe.trans, result.rpe.rot_deg
    per = f"/{rpe_delta:g}s" if result.rpe.delta_s is not None else ", all pairs"
    sampled = f", at most {rpe_max_pairs} sampled" if rpe_max_pairs else ""
    typer.echo(f"RPE pairs            {result.rpe.pairs} ({result.rpe.mode.value}{sampled})")
    typer.echo(f"RPE trans (m{per})   rmse {t.rmse:.4f}  mean {t.mean:.4f}  median {t.median:.4f}  max {t.max:.4f}")
    typer.echo(f"RPE rot (deg{per})   rmse {r.rmse:.3f}  mean {r.mean:.3f}  median {r.median:.3f}  max {r.max:.3f}")
