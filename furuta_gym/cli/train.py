"""``furuta-gym train``: train a DeLaN / APHYNITY / augmented DeLaN model on trajectory data.

Example::

    furuta-gym train --system nmsd --model dln --loss prop --data train.csv --out runs/nmsd_dln
    furuta-gym train --system furuta --model dln --loss prop --data free.csv \\
        --forced forced.csv --out runs/furuta_dln --epochs 200,20
    furuta-gym train ... --out runs/furuta_dln --resume      # continue a killed run
    furuta-gym train --system furuta --model dln --loss prop --data qube:1-5 --out runs/real_dln \
        --horizons itau,2,0.1s --epochs 2000,4,1               # measured logs (real QUBE runs)

DATA is generated data or measured logs (``qube:RUNS`` for the real QUBE-Servo runs shipped with
the package, or files read with ``--column-map/--sign/--offset``): absent velocities are estimated
(``--velocity``), the start is dropped (``--skip``) and logs without velocities are cut into
elementary trajectories of ``--split`` seconds (the paper's 1 s for its experimental Furuta data).

Writes ``DIR/model.eqx`` (load with ``furuta_gym.training.checkpoint.load_model``), the
resumable ``DIR/train_state.eqx``, periodic ``DIR/model_epoch*.eqx`` and ``DIR/history.json``.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from ..systems import SYSTEMS
from ._logs import add_log_arguments, prepared_logs


def _ints(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None


def _rates(text: str) -> float | tuple[float, ...]:
    try:
        rates = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or comma-separated numbers, got {text!r}") from None
    return rates[0] if len(rates) == 1 else rates


def _horizons(text: str) -> tuple[int | float | None, ...]:
    from ..training.loss_kinds import INTEGRAL_ONLY

    out = []
    for v in text.split(","):
        v = v.strip()
        if v.lower() == INTEGRAL_ONLY.name:  # a stage of L_Iτ alone (prop)
            out.append(None)
            continue
        try:
            out.append(float(v[:-1]) if v.endswith("s") else int(v))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"horizons are samples (e.g. 2), seconds with an 's' (e.g. 1s) or 'itau' (a stage "
                f"of L_Iτ alone, with --loss prop), got {v!r}"
            ) from None
    return tuple(out)


def add_learned_spring_argument(parser: argparse.ArgumentParser) -> None:
    """``--learned-spring JOINT``: a spring with learned k and rest in a DeLaN's potential."""
    parser.add_argument(
        "--learned-spring",
        action="append",
        default=None,
        metavar="JOINT",
        help="give the DeLaN and augmented-DeLaN potentials a learned spring ½k(q − q_ref)² on "
        "JOINT (repeatable; e.g. alpha, a rotor cable the diagnosis found: their periodic "
        "potential cannot hold one that winds up over turns); dln / adln models only",
    )


def model_hparams(args: argparse.Namespace) -> dict | None:
    """The model hyper-parameters the command line sets (None: the system's defaults)."""
    hp = {}
    if getattr(args, "hidden", None):
        hp["hidden"] = args.hidden
    if args.learned_spring:
        hp["springs"] = tuple(args.learned_spring)
    return hp or None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    _add_run_arguments(parser)
    _add_recipe_arguments(parser)
    parser.add_argument("--checkpoint-every", type=int, help="model snapshot every N epochs")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_log_arguments(
        parser,
        None,
        "cut each log into elementary trajectories of this many seconds (0: keep whole); default: "
        "logs without velocities (measured) are cut as the paper cuts its experimental data, 1 s "
        "Furuta (2 s N-MSD), and generated data carrying velocities are kept whole",
    )


def _add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """What is trained on what, and where it goes."""
    parser.add_argument("--system", required=True, choices=sorted(SYSTEMS))
    parser.add_argument(
        "--model", required=True, choices=["dln", "aph", "adln"], help="DeLaN, APHYNITY or augmented DeLaN"
    )
    parser.add_argument(
        "--loss",
        required=True,
        choices=["traj", "aph", "prop", "itau"],
        help="L_traj, L_aph (‖F_a‖ + λL_traj), L_prop (L_Iτ + λL_traj), or L_Iτ alone",
    )
    parser.add_argument(
        "--data",
        required=True,
        nargs="+",
        metavar="DATA",
        help="training trajectories: CSV (.csv.gz too), NPZ or MAT in the long format, "
        "several pooled; 'qube:RUNS' (e.g. qube:1-5) takes the real QUBE-Servo runs "
        "shipped with the package",
    )
    parser.add_argument(
        "--forced",
        help="forced trajectory file for the overall-scale fit "
        "(needed after training on free, u = 0, data; read like DATA, never split)",
    )
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out")


def _add_recipe_arguments(parser: argparse.ArgumentParser) -> None:
    """The training settings (default: the reproduction's recipe for the system)."""
    parser.add_argument(
        "--paper", action="store_true", help="the paper's recipe (50k+10k / 5k+1k epochs, full batch): hours on a CPU"
    )
    parser.add_argument("--epochs", type=_ints, help="epochs per stage, e.g. 200,20")
    parser.add_argument(
        "--horizons",
        type=_horizons,
        help="horizon per stage: samples, seconds or 'itau' (L_Iτ alone, with --loss prop), "
        "e.g. itau,2,1s (default 2,1s Furuta; 2,2s N-MSD)",
    )
    parser.add_argument(
        "--lr", type=_rates, help="Adam learning rate, one value or one per stage, e.g. 1e-2,1e-3,1e-3 (default 1e-3)"
    )
    parser.add_argument("--weight-decay", type=float, help="AdamW weight decay (default 1e-5)")
    parser.add_argument("--batch-size", type=int, help="trajectory windows per step; 0 = full batch")
    parser.add_argument("--lambda", dest="lam", type=float, help="λ of L_prop / initial λ of L_aph (default 1)")
    parser.add_argument(
        "--lambda-step",
        type=float,
        help="dual-ascent step τ₂ on λ after each epoch (default 1000 for aph, 0 otherwise)",
    )
    parser.add_argument(
        "--quadrature",
        choices=["trapezoid", "simpson", "hermite"],
        help="L_Iτ rule (default trapezoid, the paper's; hermite resolves the motion "
        "between samples from q and q̇ and all but removes the quadrature floor)",
    )
    parser.add_argument(
        "--integral-span",
        type=int,
        help="quadrature intervals summed into one L_Iτ residual (default 1, the paper's); "
        "a few estimator time constants on encoder logs with estimated velocities",
    )
    parser.add_argument("--hidden", type=_ints, help="MLP widths, e.g. 16,16")
    add_learned_spring_argument(parser)
    parser.add_argument("--seed", type=int, help="random seed (weights, shuffling)")


def _describe_data(args, trajs, notes) -> dict:
    """Say what the logs became; the returned record goes beside the run as ``data.json`` (the
    checkpoint's data hash identifies the data but cannot say where they came from)."""
    dur = sorted({round(len(tr) * tr.dt, 3) for tr in trajs})
    span = f"{dur[0]:g} s" if len(dur) == 1 else f"{dur[0]:g}-{dur[-1]:g} s"
    print(
        f"training data: {len(trajs)} trajectories of {span} from {' '.join(args.data)}"
        + "".join(f"; {n}" for n in notes)
    )
    return {
        "data": args.data,
        "forced": args.forced,
        "n_trajectories": len(trajs),
        "notes": notes,
        **{k: getattr(args, k) for k in ("column_map", "sign", "offset", "skip", "velocity", "cutoff", "split")},
    }


def _config(args, free_release: bool = False):
    """The TrainSettings the options ask for; on measured free releases (``free_release``: logs
    whose velocities were estimated, no input anywhere) L_prop without ``--lambda`` takes the
    free-release λ."""
    from ..training.loss_kinds import loss_kind
    from ..training.recipe import FREE_RELEASE_LAMBDA
    from ..training.train import TrainSettings

    overrides = {}
    for name, key in [
        ("epochs", "epochs"),
        ("horizons", "horizons"),
        ("lr", "learning_rate"),
        ("weight_decay", "weight_decay"),
        ("lam", "lambda_traj"),
        ("lambda_step", "lambda_step"),
        ("quadrature", "quadrature"),
        ("integral_span", "integral_span"),
        ("seed", "seed"),
        ("checkpoint_every", "checkpoint_every"),
    ]:
        value = getattr(args, name)
        if value is not None:
            overrides[key] = value
    if args.batch_size is not None:
        overrides["batch_size"] = None if args.batch_size == 0 else args.batch_size
    if args.epochs is not None and args.horizons is None and len(args.epochs) == 1:
        overrides["horizons"] = (2,)
    if free_release and loss_kind(args.loss).proposed and args.lam is None and not args.paper:
        overrides["lambda_traj"] = FREE_RELEASE_LAMBDA
        print(f"measured free releases: L_prop with λ = {FREE_RELEASE_LAMBDA:g} (--lambda to choose; docs/learning.md)")
    overrides["progress"] = not args.no_progress
    make = TrainSettings.paper if args.paper else TrainSettings.for_system
    return make(args.system, **overrides)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..models import model_kind
    from ..training.free_dynamics import free_dynamics_summary
    from ..training.loss_kinds import INTEGRAL_TERM, PENALTY_TERM, TRAJECTORY_TERM
    from ..training.train import FREE_DYNAMICS_FILE, train

    hparams = model_hparams(args)
    if hparams and "springs" in hparams and model_kind(args.model).analytic_prior:
        raise ValueError("--learned-spring: APHYNITY's potential is its physics prior's; use --model dln or adln")
    trajs, notes, measured = prepared_logs(args.data, args)
    forced = prepared_logs([args.forced], args, split=None).trajectories if args.forced else None
    data_info = _describe_data(args, trajs, notes)
    from ._cache import enable_compilation_cache

    enable_compilation_cache()  # compiling once per machine, not once per run
    free = not any(np.any(np.asarray(tr.u) != 0) for tr in trajs)
    config = _config(args, free_release=free and measured)
    try:
        model, history = train(
            args.model,
            args.system,
            args.loss,
            trajs,
            config,
            args.out,
            resume=args.resume,
            forced_trajs=forced,
            hparams=hparams,
        )
    except KeyboardInterrupt as exc:  # Ctrl-C / SIGTERM: every finished epoch is saved
        import sys

        print(f"furuta-gym train: {exc or 'interrupted'}", file=sys.stderr)
        return 130
    # written once the run is this one's (a refused --out keeps the data record it had)
    (Path(args.out) / "data.json").write_text(json.dumps(data_info, indent=1) + "\n")
    last = history[-1] if history else {}
    shown = ("epoch", TRAJECTORY_TERM, INTEGRAL_TERM, PENALTY_TERM, "lambda")
    summary = {k: v for k, v in last.items() if k in shown}
    print(f"trained {args.system} {args.model} with L_{args.loss}: {json.dumps(summary)}")
    print(f"model: {args.out}/model.eqx")
    check = Path(args.out) / FREE_DYNAMICS_FILE
    if check.exists():
        print(free_dynamics_summary(json.loads(check.read_text())) + f" ({check})")
    return 0
