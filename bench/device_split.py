"""The batched env's copies on two host devices against one (``devices=``, jax.sharding).

    python bench/device_split.py [--repeats 3] [--seconds 1.0] [--no-write]

Splits this machine's CPU into two JAX host devices (``--xla_force_host_platform_device_count=2``,
set before JAX starts) and measures, side by side in one process, the state-steps/s (copies ×
env steps per second) of :class:`furuta_gym.envs.vector.FurutaVectorEnv` over an untrained DeLaN
of the default architecture with ``devices=1`` (the first host device only) and ``devices=2``
(the copies split in halves, one step on both devices). Writes its section of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys

# before JAX starts: the host platform's device count is read once
if "xla_force_host_platform_device_count" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2").strip()
os.environ.setdefault("MUJOCO_GL", "egl")

from _generated import machine, write_section  # noqa: E402
from batched_speed import batched_env_rate  # noqa: E402

START, END = "<!-- bench/device_split.py:start -->", "<!-- bench/device_split.py:end -->"
NS = (256, 1024, 4096)


def measure(model, seconds: float, repeats: int) -> list[tuple]:
    """``(N, rate on 1 device, rate on 2)`` per N; the two measured one after the other."""
    rows = []
    for n in NS:
        one, _ = batched_env_rate(model, n, seconds, repeats, devices=1)
        two, _ = batched_env_rate(model, n, seconds, repeats, devices=2)
        rows.append((n, one, two))
        print(
            f"N={n}: 1 device {one:,.0f} ({one.cpu:,.0f}/CPU-s), 2 devices {two:,.0f} "
            f"({two.cpu:,.0f}/CPU-s): {two / one:.2f}x",
            flush=True,
        )
    return rows


def section(rows, repeats: int) -> str:
    lines = [
        START,
        "## Batched env over devices: `bench/device_split.py`",
        "",
        f"{machine()}; {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC. "
        "`FurutaVectorEnv(N, dynamics=<untrained DeLaN>, devices=k)` in one process whose CPU is "
        "split into two JAX host devices (`--xla_force_host_platform_device_count=2`). "
        f"State-steps/s (copies × `step` calls per second), wall clock and per CPU-second, best of {repeats}, "
        "measured side by side. Each device computes exactly what one device computes for its half of "
        "the copies; against one device stepping all of them the two agree to 1e-12, XLA's kernels "
        "for another batch shape (tests/test_vector_devices.py).",
        "",
        "| N | 1 device | 2 devices | 2 / 1 (wall) | 1 device per CPU-s | 2 devices per CPU-s |",
        "|---|---|---|---|---|---|",
    ]
    for n, one, two in rows:
        lines.append(f"| {n} | {one:,.0f} | {two:,.0f} | {two / one:.2f} | {one.cpu:,.0f} | {two.cpu:,.0f} |")
    lines.append(END)
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=1.0, help="wall time of one timed run")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)

    import jax

    import furuta_gym
    from furuta_gym.models import make_model

    furuta_gym.enable_x64()
    if len(jax.devices()) < 2:
        ap.error(f"needs two JAX devices, found {jax.devices()} (XLA_FLAGS set too late?)")
    model = make_model("furuta", "dln", key=jax.random.PRNGKey(0))
    text = section(measure(model, args.seconds, args.repeats), args.repeats)
    if args.no_write:
        print(text)
    else:
        write_section(text, START, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
