"""``furuta-gym rollout``: run an env with a simple policy; write a plot (and a video, a log).

Examples::

    furuta-gym rollout --system furuta --policy chirp --seconds 5 --out rollout.png --video rollout.mp4
    furuta-gym rollout --system nmsd --dynamics analytic --policy random --out nmsd.png
    furuta-gym rollout --system furuta --dynamics runs/delan.eqx --plant cable_spring --out cp.png

Existing outputs are never overwritten unless ``--overwrite`` is given.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, cast

import numpy as np

from ..systems import SYSTEMS

POLICIES = ("zero", "chirp", "random")
VIDEO_FPS = 30


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--system", choices=sorted(SYSTEMS), default="furuta")
    parser.add_argument(
        "--dynamics",
        default="mujoco",
        help="'mujoco' (ground truth, default), 'analytic', or a checkpoint path",
    )
    parser.add_argument(
        "--policy",
        choices=POLICIES,
        default="chirp",
        help="zero input, a linear chirp, or uniform random actions (default chirp)",
    )
    parser.add_argument(
        "--amplitude", type=float, default=None, help="chirp/random amplitude (default: 60%% of the action limit)"
    )
    parser.add_argument("--seconds", type=float, default=5.0, help="rollout length (default 5 s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--state", type=float, nargs="+", default=None, help="initial state (q..., q_dot...), e.g. --state 0 3.0 0 0"
    )
    parser.add_argument(
        "--plant", action="append", default=None, help="plant variant preset (repeatable), e.g. cable_spring, coulomb"
    )
    parser.add_argument("--out", type=Path, default=Path("rollout.png"), help="PNG plot path")
    parser.add_argument("--video", type=Path, default=None, help="also write an .mp4 or .gif")
    parser.add_argument(
        "--data", type=Path, default=None, help="also write the trajectory (CSV or NPZ, the package's data format)"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace existing outputs")


def _policy(name: str, env, amplitude: float, seconds: float, rng: np.random.Generator):
    from ..models import system_definition
    from ..signals import chirp

    f1 = system_definition(env.unwrapped.system).chirp_end_frequency
    if name == "zero":
        return lambda t: 0.0
    if name == "chirp":
        return lambda t: float(chirp(t, 0.1, f1, max(seconds, 1e-9), amplitude=amplitude))
    return lambda t: float(rng.uniform(-amplitude, amplitude))


def run(args) -> int:
    import gymnasium as gym

    import furuta_gym  # noqa: F401  (registers the envs)

    from ..data import Trajectory, save_trajectories
    from ..envs import ENV_IDS, Camera, Episode, LagrangianEnv

    _check_arguments(args)
    kwargs: dict[str, Any] = dict(dynamics=args.dynamics, episode=Episode(seconds=None))
    if args.plant:
        kwargs["plant"] = args.plant
    if args.video is not None:
        kwargs.update(render_mode="rgb_array", camera=Camera(width=480, height=360))
    env = gym.make(ENV_IDS[args.system], **kwargs)
    unwrapped = cast(LagrangianEnv, env.unwrapped)
    amplitude = 0.6 * unwrapped.max_action if args.amplitude is None else float(args.amplitude)
    rng = np.random.default_rng(args.seed)
    policy = _policy(args.policy, env, amplitude, args.seconds, rng)

    every = max(1, int(round(1.0 / (VIDEO_FPS * unwrapped.dt))))
    ts, xs, us, rewards, frames, ended = _roll_out(env, unwrapped.dt, policy, args, every)
    env.close()
    t, x = np.array(ts), np.array(xs)
    u = np.array(us + [us[-1] if us else 0.0])  # input held: repeat the last sample

    _plot(args.out, unwrapped, t, x, u, rewards, args, ended)
    written = [args.out]
    if args.video is not None:
        _write_video(args.video, frames, fps=1.0 / (every * unwrapped.dt))
        written.append(args.video)
    if args.data is not None:
        n = unwrapped.system_spec.n_dof
        traj = Trajectory(t=t, q=x[:, :n], u=u[:, None], qd=x[:, n:], name="0")
        save_trajectories(args.data, [traj], args.system, overwrite=args.overwrite)
        written.append(args.data)
    print(
        f"{ENV_IDS[args.system]} dynamics={args.dynamics} policy={args.policy}: {len(us)} steps, "
        f"{t[-1]:.3f} s{ended}, return {sum(rewards):.3f}; wrote {', '.join(map(str, written))}"
    )
    return 0


def _check_arguments(args) -> None:
    """Output paths of the right kinds, none overwritten unless asked, and a positive duration."""
    outputs = [p for p in (args.out, args.video, args.data) if p is not None]
    if args.out.suffix.lower() != ".png":
        raise ValueError(f"--out must be a .png path, got {str(args.out)!r}")
    if args.video is not None and args.video.suffix.lower() not in (".mp4", ".gif"):
        raise ValueError(f"--video must end in .mp4 or .gif, got {str(args.video)!r}")
    if not args.overwrite:
        for p in outputs:
            if p.exists():
                raise FileExistsError(f"{p}: exists; refusing to overwrite (pass --overwrite)")
    if not (np.isfinite(args.seconds) and args.seconds > 0):
        raise ValueError(f"--seconds must be > 0, got {args.seconds}")


def _roll_out(env, dt: float, policy, args, every: int):
    """Reset and step the env for ``args.seconds`` (or until its episode ends): times, states,
    actions, rewards, video frames (every ``every`` steps) and how it ended."""
    options = None if args.state is None else {"state": np.asarray(args.state, dtype=float)}
    _, info = env.reset(seed=args.seed, options=options)
    steps = int(round(args.seconds / dt))
    ts, xs, us, rewards = [0.0], [info["state"]], [], []
    frames = [env.render()] if args.video is not None else []
    ended = ""
    for k in range(steps):
        action = np.array([policy(k * dt)])
        _, reward, terminated, truncated, info = env.step(action)
        us.append(info["action"])
        rewards.append(reward)
        ts.append(info["time"])
        xs.append(info["state"])
        if args.video is not None and (k + 1) % every == 0:
            frames.append(env.render())
        if terminated or truncated:
            ended = " (diverged)" if info["diverged"] else " (episode ended)"
            break
    return ts, xs, us, rewards, frames, ended


def _plot(path: Path, env, t, x, u, rewards, args, ended: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spec = env.system_spec
    n = spec.n_dof
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for j in range(n):
        axes[0].plot(t, x[:, j], label=f"{spec.joint_names[j]} [{spec.joint_units[j]}]")
        axes[1].plot(t, x[:, n + j], label=f"{spec.joint_names[j]}_dot [{spec.joint_units[j]}/s]")
    axes[2].step(t, u, where="post", color="k", label=f"u [{spec.input_units[0]}]")
    axes[0].set_ylabel("position")
    axes[1].set_ylabel("velocity")
    axes[2].set_ylabel("input")
    axes[2].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    fig.suptitle(
        f"{spec.name}: dynamics={args.dynamics}, policy={args.policy}, seed={args.seed}"
        f"{ended}, return {sum(rewards):.2f}",
        fontsize=10,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _write_video(path: Path, frames, fps: float) -> None:
    import imageio.v2 as imageio

    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        imageio.mimsave(path, frames, duration=1000.0 / fps, loop=0)
    else:
        imageio.mimsave(path, frames, fps=fps, macro_block_size=8)
