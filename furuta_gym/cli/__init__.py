"""The ``furuta-gym`` command (also ``python -m furuta_gym``).

Each subcommand lives in its own module ``furuta_gym.cli.<name>`` defining
``add_arguments(parser)`` and ``run(args) -> int``; this dispatcher imports only the one asked
for, so ``furuta-gym --help`` stays fast and one broken subcommand cannot break the others.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import sys

__all__ = ["main", "SUBCOMMANDS"]

# name -> one-line help. Order is the order shown in --help.
SUBCOMMANDS: dict[str, str] = {
    "demo": "the main job on small defaults: generate, train, swap, control, diagnose",
    "rollout": "run an env from the command line and write a plot (and a video)",
    "generate": "generate training/test data from the MuJoCo ground truth",
    "train": "train a DeLaN / APHYNITY / augmented DeLaN model",
    "evaluate": "evaluate a checkpoint on test data (log10 RMSE metrics)",
    "control": "closed-loop benchmark of a controller designed on one model, run on another plant",
    "inspect": "what a log holds before diagnosing or training: units, gaps, ranges, what it can identify",
    "diagnose": "find which physical effect a model is missing on measured data",
    "reproduce": "regenerate the paper's Tables 1 and 2",
}


def _available() -> dict[str, str]:
    found = {}
    for name, help_ in SUBCOMMANDS.items():
        if importlib.util.find_spec(f"furuta_gym.cli.{name}") is not None:
            found[name] = help_
    return found


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="furuta-gym",
        description="Lagrangian models, Gymnasium envs and controllers for the Furuta pendulum "
        "and the nonlinear mass-spring-damper.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, help_ in _available().items():
        p = sub.add_parser(name, help=help_, description=help_)
        importlib.import_module(f"furuta_gym.cli.{name}").add_arguments(p)
    return parser


def headless_gl_default(environ, platform: str) -> dict[str, str]:
    """``{"MUJOCO_GL": "egl"}`` on a Linux machine without a display and no choice of the user's;
    nothing elsewhere (macOS and Windows have no EGL backend: MuJoCo would refuse to import)."""
    if "MUJOCO_GL" in environ or environ.get("DISPLAY") or not platform.startswith("linux"):
        return {}
    return {"MUJOCO_GL": "egl"}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # The CLI is an application, not a library: it owns the process, so it switches float64 on
    # up front (silently) before any JAX array exists.
    from .._x64 import enable_x64

    enable_x64()
    # Headless by default: MuJoCo's offscreen rendering needs a GL backend chosen before it is
    # first imported; EGL works on a machine without a display (the user's choice wins).
    os.environ.update(headless_gl_default(os.environ, sys.platform))
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    module = importlib.import_module(f"furuta_gym.cli.{args.command}")
    try:
        return int(module.run(args) or 0)
    except (ValueError, FileNotFoundError, FileExistsError) as exc:
        # Bad input: one clear line, no traceback.
        print(f"furuta-gym {args.command}: error: {exc}", file=sys.stderr)
        return 2
