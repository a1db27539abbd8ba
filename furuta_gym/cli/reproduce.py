"""``furuta-gym reproduce``: regenerate the paper's Tables 1 and 2 (simulated) and its figures."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

from ..systems import SYSTEMS
from .train import add_learned_spring_argument, model_hparams

__all__ = ["add_arguments", "add_executor_arguments", "config_from_args", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    _add_selection_arguments(parser)
    _add_data_arguments(parser)
    _add_execution_arguments(parser)
    parser.add_argument("--no-figures", action="store_true", help="tables only")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def _add_selection_arguments(parser: argparse.ArgumentParser) -> None:
    """What runs: scale, seeds, systems, pairs and epochs."""
    parser.add_argument(
        "--quick",
        action="store_true",
        help="scaled-down data and a few epochs: the whole pipeline in minutes (not the paper's numbers)",
    )
    parser.add_argument("--out", default=None, help="output folder (default results/reproduce[_quick])")
    parser.add_argument("--seed", type=int, default=0, help="data seed (and the model seed without --seeds)")
    parser.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=None,
        metavar="SEED",
        help="model-initialisation seeds, e.g. --seeds 0 1 2: every model is trained once per seed "
        "and each cell reads mean ± std over them (default: --seed alone)",
    )
    parser.add_argument(
        "--system",
        choices=sorted(SYSTEMS),
        action="append",
        dest="systems",
        help="only this system (repeatable; default both)",
    )
    parser.add_argument(
        "--pair",
        action="append",
        dest="pairs",
        metavar="MODEL:LOSS",
        help="only this model × loss pair, e.g. dln:prop (repeatable; default all six of the paper)",
    )
    parser.add_argument(
        "--epochs",
        type=int,
        nargs=2,
        metavar=("STAGE1", "STAGE2"),
        help="epochs of the 2-step and the long-horizon stage of the L_traj / L_aph runs (both systems)",
    )
    parser.add_argument(
        "--prop-epochs",
        type=int,
        nargs=3,
        metavar=("ITAU", "STAGE1", "STAGE2"),
        help="epochs of the L_prop runs: L_Iτ alone, then the 2-step and long-horizon stages of "
        "L_Iτ + λ·L_traj (both systems)",
    )


def _add_data_arguments(parser: argparse.ArgumentParser) -> None:
    """Which plant and sensor make the data, and how the L_prop runs read it."""
    parser.add_argument(
        "--ground-truth",
        choices=["auto", "mujoco", "analytic"],
        default="auto",
        help="data from the MuJoCo model (auto: when available) or the analytic model",
    )
    parser.add_argument(
        "--plant",
        default=None,
        metavar="FILE",
        help="generate the data on this plant (a diagnosis JSON from `diagnose --json`, or an MJCF "
        "from `--mjcf`): the paper's protocol on your calibrated rig; the state columns then "
        "sit beside the paper's experimental ones",
    )
    parser.add_argument(
        "--sensor",
        choices=["exact", "experiment"],
        default="exact",
        help="exact states (the paper's simulated data) or as the QUBE measures them: 2048-count "
        "encoders and the paper's derivative filter for velocities (its experiments)",
    )
    parser.add_argument(
        "--integral-span",
        type=int,
        default=1,
        metavar="N",
        help="quadrature intervals summed into one L_Iτ residual in the L_prop runs (default 1, the "
        "paper's); a few velocity-filter time constants on --sensor experiment data",
    )
    parser.add_argument(
        "--training-velocities",
        choices=["recorded", "zero_phase"],
        default="recorded",
        help="train (and fit the scale) on the sensor's velocities or on velocities re-estimated "
        "offline from the angles without lag (the derivative filter lags by ~16 ms); the test "
        "sets are scored as recorded",
    )
    parser.add_argument(
        "--itau-normalization",
        choices=["momentum", "joint_momentum"],
        default=None,
        help="L_Iτ's normaliser in every run (default: the recipe's, by the data: momentum on free "
        "data); joint_momentum divides each joint's residual by its own momentum changes, so a "
        "model cannot lighten a joint whose forces it cannot express",
    )
    add_learned_spring_argument(parser)
    parser.add_argument(
        "--quadrature",
        choices=["trapezoid", "simpson", "hermite"],
        default=None,
        help="L_Iτ's rule and the scale fit's, for every run (default: the reproduction's recipe, "
        "furuta_gym.training.reproduce.REPRODUCE_QUADRATURE, and FULL_PROP_QUADRATURE for "
        "the L_prop models named there)",
    )


def _add_execution_arguments(parser: argparse.ArgumentParser) -> None:
    """Where and how many models train at once."""
    parser.add_argument(
        "--jobs",
        type=int,
        default=None,
        metavar="N",
        help="train N models at once in separate processes (default: the number of CPU cores, at most 8)",
    )
    add_executor_arguments(parser)


def add_executor_arguments(parser: argparse.ArgumentParser) -> None:
    """``--executor``, ``--address`` and ``--cpus-per-task``: the local pool or Ray tasks (also the
    options of studies/select_option.py, which trains its candidates the same way)."""
    parser.add_argument(
        "--executor",
        choices=["local", "ray"],
        default="local",
        help="where the models train: this machine's processes (default) or Ray tasks, one per "
        "model × seed (pip install 'furuta-gym[cluster]'); the run folders are the same",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="with --executor ray: the Ray cluster to join (e.g. auto, or ray://HOST:10001); without "
        "it a local Ray instance runs --jobs tasks at once. On several machines --out must be "
        "a folder all of them see at the same path",
    )
    parser.add_argument(
        "--cpus-per-task",
        type=int,
        default=1,
        metavar="N",
        help="with --executor ray: CPUs each model's task asks for (and the threads it may use)",
    )


def _train_overrides(args) -> dict | None:
    """The TrainSettings fields the command line sets for every run (None: the recipe's)."""
    chosen = {"quadrature": args.quadrature, "normalize": args.itau_normalization}
    return {k: v for k, v in chosen.items() if v} or None


def config_from_args(args: argparse.Namespace):
    """``(output folder, ReproduceSettings)`` of parsed ``furuta-gym reproduce`` arguments."""
    from ..training.reproduce import PAPER_PAIRS, ReproduceSettings

    jobs = args.jobs if args.jobs is not None else max(1, min(os.cpu_count() or 1, 8))
    if jobs < 1:
        raise ValueError(f"--jobs must be at least 1, got {jobs}")
    seeds = tuple(args.seeds) if args.seeds else (args.seed,)
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"--seeds must differ, got {' '.join(map(str, seeds))}")
    systems = tuple(dict.fromkeys(args.systems)) if args.systems else ("nmsd", "furuta")
    epochs = {s: tuple(args.epochs) for s in systems} if args.epochs else None
    prop_epochs = {s: tuple(args.prop_epochs) for s in systems} if args.prop_epochs else None
    pairs = PAPER_PAIRS
    if args.pairs:
        pairs = []
        for text in args.pairs:
            kind, sep, loss = text.partition(":")
            if not sep or (kind, loss) not in PAPER_PAIRS:
                raise ValueError(
                    f"--pair {text!r}: expected MODEL:LOSS, one of " + ", ".join(f"{k}:{l}" for k, l in PAPER_PAIRS)
                )
            pairs.append((kind, loss))
        pairs = tuple(p for p in PAPER_PAIRS if p in set(pairs))  # the paper's row order
    out = Path(args.out) if args.out else Path("results") / ("reproduce_quick" if args.quick else "reproduce")
    config = ReproduceSettings(
        quick=args.quick,
        seeds=seeds,
        data_seed=args.seed,
        systems=systems,
        pairs=pairs,
        epochs=epochs,
        prop_epochs=prop_epochs,
        ground_truth=args.ground_truth,
        plant=args.plant,
        sensor=args.sensor,
        integral_span=args.integral_span,
        training_velocities=args.training_velocities,
        train_overrides=_train_overrides(args),
        model_overrides=model_hparams(args),
        figures=not args.no_figures,
        progress=not args.no_progress,
        jobs=jobs,
        executor=args.executor,
        address=args.address,
        cpus_per_task=args.cpus_per_task,
    )
    return out, config


def run(args: argparse.Namespace) -> int:
    from ..training.reproduce import reproduce

    out, config = config_from_args(args)
    if config.executor == "ray":  # before any data is generated: one line naming the extra
        from ..training.reproduce import require_executor

        try:
            require_executor(config)
        except ImportError as exc:
            raise ValueError(str(exc)) from None
    # a persistent compilation cache makes a resumed or repeated run skip most JAX compiles
    from ._cache import enable_compilation_cache

    enable_compilation_cache()
    command = "furuta-gym " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:] else None
    paths = reproduce(out, config, command=command)
    for name, path in paths.items():
        print(f"{name:24s} {path}")
    return 0
