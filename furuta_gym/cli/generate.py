"""``furuta-gym generate``: the paper's training and test datasets as measured-data CSV files."""

from __future__ import annotations

import argparse

from ..systems import SYSTEMS

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--system", required=True, choices=sorted(SYSTEMS))
    parser.add_argument("--out", required=True, help="output folder (CSV files + manifest.json)")
    parser.add_argument("--seed", type=int, default=0, help="random seed for the initial states")
    parser.add_argument("--quantize", action="store_true", help="round angles to 2048 counts/rev (Furuta)")
    parser.add_argument(
        "--noise",
        type=float,
        default=0.0,
        metavar="STD",
        help="Gaussian position-noise std (rad or m) per 500 Hz sensor sample",
    )
    parser.add_argument(
        "--velocity-noise",
        type=float,
        default=0.0,
        metavar="STD",
        help="Gaussian noise std added to exact velocities",
    )
    parser.add_argument(
        "--velocity",
        choices=["exact", "filter"],
        default="exact",
        help="exact simulated velocities, or the paper's derivative filter (ω0 100, ξ 0.8)",
    )
    parser.add_argument("--small", action="store_true", help="a scaled-down recipe for quick runs")
    parser.add_argument(
        "--ground-truth",
        choices=["auto", "mujoco", "analytic"],
        default="auto",
        help="auto: the MuJoCo model when its backend is available, else the analytic model",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace existing files in --out")


def run(args: argparse.Namespace) -> int:
    from ..sensors import Sensors
    from ..signals import ENCODER_COUNTS_PER_REV
    from ..systems import get_spec
    from ..training.datagen import generate

    if args.velocity_noise and args.velocity == "filter":
        raise ValueError("--velocity-noise applies to exact velocities, not --velocity filter")
    spec = get_spec(args.system)
    if args.quantize and not any(spec.angular):
        raise ValueError(
            f"--quantize: {spec.name} has no encoder angles to quantise (its joints are {spec.joint_names})"
        )
    sensor = Sensors(
        encoder_counts=ENCODER_COUNTS_PER_REV if args.quantize else None,
        measurement_noise=(args.noise, args.velocity_noise),
        velocity=args.velocity,
    )
    paths = generate(
        args.system,
        args.out,
        seed=args.seed,
        small=args.small,
        sensor=sensor,
        ground_truth=args.ground_truth,
        overwrite=args.overwrite,
    )
    for name, path in paths.items():
        print(f"{name:12s} {path}")
    return 0
