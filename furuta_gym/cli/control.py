"""``furuta-gym control``: closed-loop benchmark of a controller designed on one model, run on
another plant (paper, Fig. 4 and appendix "Controller Design").

    furuta-gym control --design analytic --plant mujoco --episodes 100 --seed 0 --json out.json \\
        [--plot fig4.png] [--video swingup.mp4]

The controller (energy swing-up through PFL, then LQR near the upright) is designed from
``--design`` — ``analytic`` or a checkpoint path written by ``furuta-gym train`` — and run on the
``--plant``: ``mujoco`` (ground truth), a MuJoCo plant preset (``cable_spring``, ``coulomb``,
``quadratic_drag``, ``weak_motor``, ``delay``), ``analytic``, or a checkpoint path. Episodes start
from exactly x0 = 0 and from ``--episodes`` seeded states near the hanging rest.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

DESCRIPTION_SUCCESS = "upright |wrap(beta - pi)| < 0.1 rad held for 2 s"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--design", default="analytic", help="design model: 'analytic' or a checkpoint path (default analytic)"
    )
    parser.add_argument(
        "--plant",
        default="mujoco",
        help="plant: 'mujoco', a MuJoCo plant preset (cable_spring, coulomb, ...), "
        "'analytic' or a checkpoint path (default mujoco)",
    )
    parser.add_argument(
        "--episodes", type=int, default=20, help="seeded starts near the hanging rest, run besides x0 = 0 (default 20)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the starts (default 0)")
    parser.add_argument("--seconds", type=float, default=8.0, help="episode length (default 8 s)")
    parser.add_argument("--json", dest="json_out", required=True, help="write the report here")
    parser.add_argument("--plot", default=None, help="PNG: alpha, beta, u of the x0 = 0 episode")
    parser.add_argument("--video", default=None, help="MP4: rendered x0 = 0 episode")
    gains = parser.add_mutually_exclusive_group()
    gains.add_argument(
        "--k-e", type=float, default=None, help="energy gain (rad/s^2 per J of the design model's potential)"
    )
    gains.add_argument("--auto-gain", action="store_true", help="pick k_e by a seeded sweep on the design model")
    parser.add_argument(
        "--acts-on",
        choices=("voltage", "pfl"),
        default="voltage",
        help="LQR acts on the voltage (default) or on the PFL input",
    )
    parser.add_argument("--voltage-limit", type=float, default=5.0, help="V (default 5)")
    parser.add_argument(
        "--sensor", action="store_true", help="measured-like observations: 2048-count encoders, filtered velocities"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace existing output files")


def load_design_model(design: str):
    """``analytic`` → the pinned analytic Furuta; otherwise a checkpoint path (a Furuta model)."""
    from furuta_gym.models import Furuta

    if design == "analytic":
        return Furuta()
    path = Path(design)
    if not path.exists():
        raise FileNotFoundError(f"--design {design!r}: expected 'analytic' or an existing checkpoint file")
    from furuta_gym.training.checkpoint import load_model

    return load_model(path, expected_system="furuta")


def plant_env_factory(plant: str, voltage_limit: float, sensor: bool, render: bool = False):
    """A zero-argument function making the Furuta env for ``--plant``."""
    import gymnasium as gym

    from furuta_gym.envs import Actuation, Episode, FurutaEnv, Sensors

    kwargs: dict = dict(actuation=Actuation(max_action=voltage_limit), episode=Episode(seconds=None))
    presets = FurutaEnv.plant_presets
    if plant in ("mujoco", "analytic"):
        kwargs["dynamics"] = plant
    elif plant in presets:
        kwargs["plant"] = plant
    elif Path(plant).exists():
        kwargs["dynamics"] = str(plant)
    else:
        raise ValueError(
            f"--plant {plant!r}: expected 'mujoco', 'analytic', a plant preset "
            f"({', '.join(sorted(presets))}) or an existing checkpoint file"
        )
    if sensor:
        kwargs.update(sensors=Sensors(encoder_counts=2048, velocity="filter"))
    if render:
        kwargs.update(render_mode="rgb_array")
    return lambda: gym.make(FurutaEnv.env_id, **kwargs)


def _check_outputs(args) -> None:
    for path in (args.json_out, args.plot, args.video):
        if path is not None and Path(path).exists() and not args.overwrite:
            raise FileExistsError(f"{path} exists; pass --overwrite to replace it")


def _summary(values):
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if v.size == 0:
        return None
    return {"median": float(np.median(v)), "max": float(v.max()), "min": float(v.min())}


def summarise(records, extra: dict) -> dict:
    """The JSON report: rates, per-metric summaries, and every episode."""
    ms = [r.metrics for r in records]
    seeded = ms[1:]
    return {
        **extra,
        "success_definition": DESCRIPTION_SUCCESS,
        "episodes_seeded": len(seeded),
        "success_rate": float(np.mean([m.success for m in seeded])) if seeded else None,
        "x0_zero": ms[0].as_dict(),
        "successes": int(sum(m.success for m in ms)),
        "episodes_total": len(ms),
        "divergences": int(sum(m.diverged for m in ms)),
        "time_to_upright_s": _summary([m.time_to_upright for m in ms if m.success]),
        "peak_voltage_V": _summary([m.peak_voltage for m in ms]),
        "control_energy_V2s": _summary([m.control_energy for m in ms]),
        "peak_abs_alpha_rad": _summary([m.peak_abs_alpha for m in ms]),
        "per_episode": [{"x0": r.x0.tolist(), **r.metrics.as_dict()} for r in records],
    }


def plot_episode(record, path: str, title: str) -> None:
    """Paper Fig. 4 style: α, β and u over time, the LQR phase shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(7, 6), sharex=True)
    t = record.t
    axes[0].plot(t, record.xs[:, 0])
    axes[0].set_ylabel("α (rad)")
    axes[1].plot(t, record.xs[:, 1])
    axes[1].axhline(np.pi, color="k", lw=0.5, ls="--")
    axes[1].set_ylabel("β (rad)")
    axes[2].step(t[:-1], record.us, where="post")
    axes[2].set_ylabel("u (V)")
    axes[2].set_xlabel("t (s)")
    if record.modes.size and record.modes.any():
        t_switch = t[int(np.argmax(record.modes > 0))]
        for ax in axes:
            ax.axvspan(t_switch, t[-1], color="C2", alpha=0.1, lw=0)
    axes[0].set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def render_video(controller, make_env, seconds: float, path: str, fps: int = 50) -> None:
    """Render the x0 = 0 episode (every control step simulated, frames at ``fps``)."""
    import imageio

    env = make_env()
    try:
        obs, _ = env.reset(seed=0, options={"state": [0.0, 0.0, 0.0, 0.0]})
        controller.reset()
        every = max(1, int(round(1.0 / (fps * env.unwrapped.dt))))
        frames = []
        for k in range(int(round(seconds / env.unwrapped.dt))):
            obs, _, terminated, _, _ = env.step(controller(obs))
            if k % every == 0:
                frames.append(env.render())
            if terminated:
                break
    finally:
        env.close()
    imageio.mimsave(path, frames, fps=fps)


def _run_record(args, ctrl, design_s: float, run_s: float) -> dict:
    """What the report records of the run: its arguments, the designed controller, timings."""
    return {
        "design": args.design,
        "plant": args.plant,
        "seed": args.seed,
        "seconds": args.seconds,
        "voltage_limit": args.voltage_limit,
        "sensor": args.sensor,
        "k_e": float(ctrl.swing_up.k_e),
        "acts_on": args.acts_on,
        "lqr_K": np.asarray(ctrl.lqr.K).tolist(),
        "lqr_closed_loop_eig_abs": np.abs(ctrl.lqr.design.closed_loop_eigenvalues).tolist(),
        "catch_angle": ctrl.catch_angle,
        "release_angle": ctrl.release_angle,
        "design_seconds": design_s,
        "run_seconds": run_s,
    }


def run(args) -> int:
    from furuta_gym.controllers import SwingUpLQR, evaluate_on_env, near_rest_starts

    if args.episodes < 0:
        raise ValueError(f"--episodes must be >= 0, got {args.episodes}")
    if not args.seconds > 2.0:
        raise ValueError(f"--seconds must exceed the 2 s hold of the success test, got {args.seconds}")
    _check_outputs(args)
    model = load_design_model(args.design)
    make_env = plant_env_factory(args.plant, args.voltage_limit, args.sensor)
    t0 = time.perf_counter()
    ctrl = SwingUpLQR.from_model(
        model,
        k_e=args.k_e,
        auto_gain=args.auto_gain,
        acts_on=args.acts_on,
        voltage_limit=args.voltage_limit,
        seed=args.seed,
    )
    design_s = time.perf_counter() - t0
    x0s = (
        np.concatenate([np.zeros((1, 4)), near_rest_starts(args.episodes, args.seed, False)])
        if args.episodes > 0
        else np.zeros((1, 4))
    )
    t0 = time.perf_counter()
    records = evaluate_on_env(ctrl, make_env, x0s, args.seconds, seed=args.seed)
    run_s = time.perf_counter() - t0
    report = summarise(records, _run_record(args, ctrl, design_s, run_s))
    Path(args.json_out).write_text(json.dumps(report, indent=2))
    if args.plot:
        plot_episode(records[0], args.plot, f"design {args.design} → plant {args.plant}, x0 = 0")
    if args.video:
        render_video(
            ctrl, plant_env_factory(args.plant, args.voltage_limit, args.sensor, True), args.seconds, args.video
        )
    sr = report["success_rate"]
    print(
        f"design {args.design} on plant {args.plant}: x0 = 0 "
        f"{'succeeded' if report['x0_zero']['success'] else 'FAILED'}"
        + (f"; {sr:.0%} of {report['episodes_seeded']} seeded starts" if sr is not None else "")
        + f"; divergences {report['divergences']}; wrote {args.json_out}"
    )
    return 0
