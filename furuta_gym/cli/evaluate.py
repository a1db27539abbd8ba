"""``furuta-gym evaluate``: the paper's log10-RMSE metrics of a checkpoint on test data.

Test data are generated sets or measured logs (``qube:RUNS``, or files read with
``--column-map/--sign/--offset/--units/--time-unit`` as every command reads a log; absent
velocities estimated, start skipped). ``--window 0.1``
scores open-loop predictions over short windows started from the measured states, the input held
over each sample period (an inverted pendulum diverges from any model over a whole log). On
measured logs there is no ground truth: the force and energy metrics, which compare with the
analytic model, are only computed for data that carry their velocities (generated sets).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ._logs import add_log_arguments, prepared_logs

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", metavar="CKPT", help="a model saved by `furuta-gym train`")
    parser.add_argument(
        "--data",
        action="append",
        required=True,
        metavar="TEST",
        help="test data in the measured-data format, or 'qube:RUNS' (e.g. qube:6-15) for the real "
        "QUBE-Servo runs shipped with the package (repeat for several test sets)",
    )
    parser.add_argument("--json", metavar="OUT", help="write the metrics as JSON here")
    parser.add_argument(
        "--no-physics",
        action="store_true",
        help="prediction metrics only (skip force decomposition and energy)",
    )
    parser.add_argument(
        "--window",
        type=float,
        metavar="SECONDS",
        help="score open-loop predictions over windows of this length started from "
        "the measured states, input held (e.g. 0.1 on the upright QUBE runs); "
        "default: one prediction per test trajectory",
    )
    parser.add_argument("--rtol", type=float, default=1e-9, help="prediction solver rtol")
    parser.add_argument("--atol", type=float, default=1e-11, help="prediction solver atol")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    add_log_arguments(
        parser, None, "cut each log into trajectories of this many seconds before scoring (default: whole logs)"
    )


def _score(model, trajs, args, physics: bool) -> dict:
    """Metrics of one test set: windows (``--window``) or whole trajectories (the paper's)."""
    from ..measured import window_errors
    from ..training.metrics import EvaluationSettings, evaluate_model, metrics_to_json

    if args.window:
        res = window_errors(model, trajs, args.window)
        metrics = {
            **res["log10_rmse"],
            "rmse": res["rmse"],
            "n_windows": res["n_windows"],
            "n_diverged": res["n_diverged"],
            "window_seconds": res["window_seconds"],
        }
        if physics:
            full = evaluate_model(model, trajs, settings=EvaluationSettings(rtol=args.rtol, atol=args.atol))
            metrics.update({k: full[k] for k in ("inertial", "coriolis", "potential", "energy")})
        metrics["n_trajectories"] = len(trajs)
        return metrics_to_json(metrics)
    settings = EvaluationSettings(rtol=args.rtol, atol=args.atol)
    return metrics_to_json(evaluate_model(model, trajs, settings=settings, physics=physics))


def run(args: argparse.Namespace) -> int:
    from ..training.checkpoint import load_model
    from ..training.metrics import DIVERGED, format_value

    out = Path(args.json) if args.json else None
    if out is not None and out.exists() and not args.overwrite:
        raise FileExistsError(f"{out}: exists; refusing to overwrite (pass --overwrite)")
    model = load_model(args.checkpoint)
    args.system = system = model.spec.name
    results = {}
    for path in args.data:
        trajs, notes, measured = prepared_logs([path], args, split=args.split, min_seconds=args.window or 0.0)
        # a measured log: the analytic model is no ground truth there
        physics = not args.no_physics and not measured
        metrics = _score(model, trajs, args, physics)
        if notes:
            metrics["note"] = "; ".join(notes) + (
                "; force and energy metrics skipped (measured data: no ground truth)"
                if measured and not args.no_physics
                else ""
            )
        results[str(path)] = metrics
        cells = "  ".join(
            f"{k}={format_value(v)}"
            for k, v in metrics.items()
            if not isinstance(v, (dict, list))
            and k not in ("n_trajectories", "note", "n_windows", "n_diverged", "window_seconds")
        )
        print(f"{path}: {cells}")
        if not args.window and any(metrics.get(k) == DIVERGED for k in model.spec.state_names):
            print(
                f"{path}: a prediction over a whole trajectory diverged; on an unstable system "
                "(the upright QUBE runs) score short windows: --window 0.1"
            )
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        payload = {
            "checkpoint": str(args.checkpoint),
            "system": system,
            "model_kind": getattr(model, "kind", type(model).__name__),
            "metric": "log10 RMSE (X: prediction diverged)",
            "settings": {"rtol": args.rtol, "atol": args.atol, "window": args.window},
            "results": results,
        }
        out.write_text(json.dumps(payload, indent=2) + "\n")
        print(f"wrote {out}")
    return 0
