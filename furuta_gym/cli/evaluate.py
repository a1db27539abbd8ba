"""``furuta-gym evaluate``: the paper's log10-RMSE metrics of a checkpoint on test data."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", metavar="CKPT", help="a model saved by `furuta-gym train`")
    parser.add_argument(
        "--data", action="append", required=True, metavar="TEST.csv",
        help="test data in the measured-data format (repeat for several test sets)",
    )
    parser.add_argument("--json", metavar="OUT", help="write the metrics as JSON here")
    parser.add_argument(
        "--no-physics", action="store_true",
        help="prediction metrics only (skip force decomposition and energy)",
    )
    parser.add_argument("--rtol", type=float, default=1e-9, help="prediction solver rtol")
    parser.add_argument("--atol", type=float, default=1e-11, help="prediction solver atol")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json file")


def run(args: argparse.Namespace) -> int:
    from ..data import load_trajectories
    from ..signals import zero_phase_velocity
    from ..training.checkpoint import load_model
    from ..training.metrics import EvaluationSettings, evaluate_model, format_value, metrics_to_json

    out = Path(args.json) if args.json else None
    if out is not None and out.exists() and not args.overwrite:
        raise FileExistsError(f"{out}: exists; refusing to overwrite (pass --overwrite)")
    model = load_model(args.checkpoint)
    system = model.spec.name
    settings = EvaluationSettings(rtol=args.rtol, atol=args.atol)
    results = {}
    for path in args.data:
        trajs = load_trajectories(path, system)
        notes = []
        for tr in trajs:
            if tr.qd is None:
                tr.qd = zero_phase_velocity(tr.q, tr.dt)
                notes.append(tr.name)
        metrics = metrics_to_json(
            evaluate_model(model, trajs, settings=settings, physics=not args.no_physics)
        )
        if notes:
            metrics["note"] = "velocities estimated with zero_phase_velocity (none in the file)"
        results[str(path)] = metrics
        cells = "  ".join(
            f"{k}={format_value(v)}" for k, v in metrics.items() if k not in ("n_trajectories", "note")
        )
        print(f"{path}: {cells}")
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        payload = {
            "checkpoint": str(args.checkpoint),
            "system": system,
            "model_kind": getattr(model, "kind", type(model).__name__),
            "metric": "log10 RMSE (X: prediction diverged)",
            "settings": {"rtol": args.rtol, "atol": args.atol},
            "results": results,
        }
        out.write_text(json.dumps(payload, indent=2) + "\n")
        print(f"wrote {out}")
    return 0
