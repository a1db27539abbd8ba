"""``furuta-gym demo``: the main job on small embedded defaults (see :mod:`furuta_gym.demo`)."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="demo_out", help="output folder (default: demo_out)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--tiny",
        action="store_true",
        help="the smallest setting (what CI runs): one short training stage, shorter runs",
    )
    parser.add_argument("--no-video", action="store_true", help="skip the rendered mp4")
    parser.add_argument(
        "--overwrite", action="store_true", help="allow writing into a folder that holds a previous demo"
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bars")


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from ..demo import DemoSettings, run_demo

    cfg = DemoSettings.tiny() if args.tiny else DemoSettings()
    cfg = dataclasses.replace(cfg, seed=args.seed, video=cfg.video and not args.no_video)
    run_demo(args.out, cfg, progress=not args.no_progress, overwrite=args.overwrite)
    return 0
