"""``furuta-gym diagnose DATA --system {furuta,nmsd}``: which physical effect is the model missing?

Fits the declared analytic model to measured data, traces the residual to an effect of the
library (:mod:`furuta_gym.effects`), adds it, refits, and reports the held-out errors before and
after (terminal table, ``--json``, ``--report`` figures). See ``docs/diagnose.md``.
"""

from __future__ import annotations

import argparse

from ..systems import SYSTEMS

# the logs are read as train and evaluate read them (one helper); the old names stay
from ._logs import add_reading_arguments, load_logs as _load, pairs as _pairs, qube_runs as _qube_runs  # noqa: F401

__all__ = ["add_arguments", "held_stop_counts", "run"]

UNSET = object()  # an option not given: the setting keeps its default


def held_stop_counts(text: str) -> float | None:
    """``--held-stop``'s value: a number of counts >= 1, or ``off`` (or 0) for None, the rule off."""
    if text.strip().lower() in ("off", "none"):
        return None
    try:
        counts = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of counts >= 1, or 'off' (or 0), got {text!r}") from None
    if counts == 0:
        return None
    if not counts >= 1:
        raise argparse.ArgumentTypeError(f"expected a number of counts >= 1, or 'off' (or 0), got {text!r}")
    return counts


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "data",
        metavar="DATA",
        nargs="+",
        help="measured data: CSV (long form, .csv.gz too), NPZ or MAT; several files "
        "are pooled. 'qube:RUNS' (e.g. qube:1-5, qube:2,7, qube) takes the real "
        "QUBE-Servo runs shipped with the package, in this project's convention",
    )
    parser.add_argument("--system", required=True, choices=sorted(SYSTEMS))
    parser.add_argument(
        "--test",
        metavar="TEST",
        nargs="+",
        help="logs never used for fitting (same format and options as DATA): "
        "errors before/after on them are reported beside the held-out split",
    )
    parser.add_argument(
        "--model",
        metavar="CKPT",
        help="diagnose this trained model (a checkpoint of `furuta-gym train`) instead "
        "of the analytic one: it is kept as it is, the library's effects are fitted around it",
    )
    parser.add_argument("--json", metavar="OUT", help="write the result as JSON (pinned schema)")
    parser.add_argument("--report", metavar="DIR", help="write figures into DIR")
    parser.add_argument(
        "--mjcf",
        metavar="OUT.xml",
        help="write the diagnosed plant as MJCF: what plain MuJoCo can run of it (native terms, dry "
        "friction as frictionloss, the input delay as the actuator's delay, ...), a comment naming what "
        "it could not express, and the whole plant as <custom> data that furuta-gym's plant= reads back",
    )
    parser.add_argument(
        "--with-inconsistent",
        action="store_true",
        help="--mjcf: include the effects reported inconsistent too, at their tested coefficients "
        "(a plant for prediction; see docs/diagnose.md, head to head)",
    )
    parser.add_argument(
        "--prediction-first",
        action="store_true",
        help="after the diagnosis, refit its model with the inconsistent effects and every joint's "
        "Coulomb friction by output error on every fit window, and keep that plant (--mjcf, the JSON's "
        "prediction_finish) if it predicts the held-out windows better; the report is unchanged",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace existing --json/--report outputs")
    _add_fit_arguments(parser)


def _add_fit_arguments(parser: argparse.ArgumentParser) -> None:
    """How the data are read and fitted."""
    add_reading_arguments(parser)
    parser.add_argument(
        "--velocity",
        choices=["zero_phase", "derivative_filter"],
        default="zero_phase",
        help="velocity estimate when DATA has none: zero-phase (offline, default) or the paper's "
        "causal derivative filter",
    )
    parser.add_argument("--cutoff", type=float, help="zero-phase velocity cutoff in Hz")
    parser.add_argument(
        "--fix",
        metavar="PARAM=VALUE,...",
        help="lumped parameters held at known values (the scale anchor), e.g. K=0.005",
    )
    parser.add_argument("--candidates", metavar="EFFECT:JOINT,...", help="restrict the library")
    parser.add_argument("--max-effects", type=int, help="at most this many effects are added (default 4)")
    parser.add_argument("--window", type=float, help="open-loop window for trajectory_rmse, s")
    parser.add_argument("--interval", type=float, help="equation-error interval, s (default 0.1)")
    parser.add_argument("--oe-windows", type=int, help="open-loop windows used by the output-error fit (default 24)")
    parser.add_argument(
        "--stop-dwell",
        type=float,
        metavar="S",
        help="also leave out of a joint's equations the intervals where it stays on one encoder count "
        "this long (a stop its dry friction held; 0.04 on open-loop sweeps whose rotor sticks; default off)",
    )
    parser.add_argument(
        "--held-stop",
        type=held_stop_counts,
        default=UNSET,
        metavar="COUNTS",
        help="leave out the intervals where a joint stays on one count while the model's other forces "
        "would have moved it, free, by more than this many counts (its dry friction held it; default 2; "
        "'off' or 0 keeps every stop's equations, as before this became the default)",
    )
    parser.add_argument(
        "--cable-laws",
        choices=["auto", "always"],
        help="Method step 11, the cable whose rest moves against a fixed cable held by a large "
        "breakaway: 'auto' where the data ask for it (default), 'always' on every joint with a spring "
        "(you know a cable is there: each law's fit and evidence are reported)",
    )
    parser.add_argument(
        "--skip",
        type=float,
        default=0.0,
        help="drop this many seconds at the start of every trajectory (start transients)",
    )


def run(args: argparse.Namespace) -> int:
    from ..diagnose import diagnose

    _check_arguments(args)
    trajs, notes = _load(args.data, args)
    test, test_notes = _load(args.test, args) if args.test else (None, [])
    from ._cache import enable_compilation_cache

    enable_compilation_cache()  # the output-error predictors compile once per machine, not once per run
    res = diagnose(
        trajs,
        args.system,
        test=test,
        model=args.model,
        fixed=_pairs(args.fix, "--fix", float) or None,
        candidates=args.candidates.split(",") if args.candidates else None,
        finish="prediction" if args.prediction_first else None,
        **_overrides(args),
    )
    res.notes[:0] = notes + test_notes  # what reading the logs did, said first
    print(res.table())
    if res.prediction is not None:
        print(res.prediction.summary())
    _write_outputs(res, args)
    return 0


def _check_arguments(args: argparse.Namespace) -> None:
    """Options that do not go together, and outputs that exist, refused before any work."""
    from pathlib import Path

    if args.with_inconsistent and not args.mjcf:
        raise ValueError("--with-inconsistent: shapes the --mjcf plant; give --mjcf OUT.xml too")
    if args.prediction_first and (args.with_inconsistent or args.model):
        raise ValueError(
            "--prediction-first: its plant refits the inconsistent effects (not with --with-inconsistent) "
            "and is a plant of lumped parameters (not with --model)"
        )
    for out in (args.json, args.mjcf):
        if out and Path(out).exists() and not args.overwrite:
            raise FileExistsError(f"{out}: exists; refusing to overwrite (pass --overwrite)")


def _overrides(args: argparse.Namespace) -> dict:
    """The diagnosis settings the options set (an option not given keeps the default)."""
    overrides = {"velocity": args.velocity}
    for key, val in (
        ("max_effects", args.max_effects),
        ("velocity_cutoff_hz", args.cutoff),
        ("window", args.window),
        ("interval", args.interval),
        ("oe_max_windows", args.oe_windows),
        ("stop_dwell", args.stop_dwell),
        ("cable_laws", args.cable_laws),
    ):
        if val is not None:
            overrides[key] = val
    if args.held_stop is not UNSET:  # None ('off') is a value here: it turns the default off
        overrides["held_stop"] = args.held_stop
    return overrides


def _write_outputs(res, args: argparse.Namespace) -> None:
    """The report's JSON, figures and plant MJCF, as asked."""
    from ..diagnose import write_report_figures as write_figures, write_report_json as write_json

    if args.json:
        print(f"wrote {write_json(res, args.json, overwrite=args.overwrite)}")
    if args.report:
        for p in write_figures(res, args.report, overwrite=args.overwrite):
            print(f"wrote {p}")
    if args.mjcf:
        from ..envs import save_mjcf

        if args.prediction_first:  # the refit plain MuJoCo runs best (without a dead band, refitted)
            assert res.prediction is not None, "--prediction-first runs the finish"
            plant = res.prediction.mujoco_plant
        else:
            plant = res.plant(include_inconsistent=args.with_inconsistent)
        print(f"wrote {save_mjcf(plant, args.mjcf, overwrite=args.overwrite)}")
