"""Accuracy of ``furuta_gym.diagnose`` on measured-like data from MuJoCo plant variants.

For every (effect, magnitude, seed): the rank of the true effect in the report, its coefficient
error, and the held-out open-loop RMSE before/after (combined and on the effect's joint); plus the
no-effect sets (any false discovery?). Prints a markdown table (pasted into docs/diagnose.md).

    python bench/diagnose_accuracy.py [--seeds 2 3] [--quick]
"""

from __future__ import annotations

import argparse
import platform
import time

import furuta_gym

furuta_gym.enable_x64()

from furuta_gym.diagnose import diagnose  # noqa: E402
from furuta_gym.effects import Effect  # noqa: E402
from furuta_gym.rigs import measured_like  # noqa: E402

GRID = [
    ("furuta", ("spring", "alpha", 5e-4)),
    ("furuta", ("spring", "alpha", 1e-3)),
    ("furuta", ("spring", "alpha", 2e-3)),
    ("furuta", ("coulomb_friction", "alpha", 3e-4)),
    ("furuta", ("coulomb_friction", "alpha", 1e-3)),
    ("furuta", ("coulomb_friction", "beta", 1e-4)),
    ("furuta", ("coulomb_friction", "beta", 3e-4)),
    ("furuta", ("coulomb_friction", "beta", 1e-3)),
    ("furuta", ("quadratic_drag", "beta", 2e-6)),
    ("furuta", ("constant_torque", "alpha", 2e-4)),
    ("furuta", ("input_delay", "u", 0.006)),
    ("furuta", ("spring", "beta", 2e-3)),
    ("furuta", ("constant_torque", "beta", 5e-5)),
    ("furuta", ("quadratic_drag", "alpha", 2e-5)),
    ("furuta", ("viscous_friction", "alpha", 2e-4)),  # in the declared model's span: must be absorbed
    ("furuta", None),
    ("nmsd", ("coulomb_friction", "p", 0.3)),
    ("nmsd", ("coulomb_friction", "p", 1.0)),
    ("nmsd", ("constant_torque", "p", 0.2)),
    ("nmsd", ("constant_torque", "p", 0.5)),
    ("nmsd", ("quadratic_drag", "p", 0.3)),  # nearly in the span of b1·ṗ + b2·ṗ³
    ("nmsd", ("input_delay", "u", 0.03)),
    ("nmsd", ("input_delay", "u", 0.05)),
    ("nmsd", None),
]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[2, 3])
    ap.add_argument("--quick", action="store_true", help="first seed only")
    args = ap.parse_args()
    seeds = args.seeds[:1] if args.quick else args.seeds
    print(f"<!-- {platform.node()} {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} -->")
    print(
        "| system | plant effect | seed | rank | found | coef. error | traj. RMSE before → after (ratio) | on the effect's joint |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for system, eff in GRID:
        for seed in seeds:
            size = dict(n_trajectories=6, duration=5.0 if system == "furuta" else 8.0)
            data = measured_like(system, [Effect(*eff)] if eff else [], seed=seed, **size)
            t0 = time.time()
            res = diagnose(data, system)
            dt = time.time() - t0
            found = ", ".join(f"{e.name}:{e.joint}" for e in res.significant) or "none"
            b, a = res.error_before, res.error_after
            comb = f"{b.trajectory_rmse:.3g} → {a.trajectory_rmse:.3g} ({b.trajectory_rmse / a.trajectory_rmse:.1f}×)"
            if eff is None:
                print(f"| {system} | none | {seed} | - | {found} | - | {comb} | - |  <!-- {dt:.0f} s -->")
                continue
            keys = [(e.name, e.joint) for e in res.effects]
            rank = keys.index(eff[:2]) + 1 if eff[:2] in keys else "-"
            ev = res.effects[rank - 1] if rank != "-" else None
            err = (
                f"{100 * (ev.coefficient - eff[2]) / eff[2]:+.0f} %"
                if ev is not None and ev.coefficient is not None
                else ev.status
                if ev
                else "-"
            )
            j = eff[1] if eff[1] != "u" else None
            jt = (
                (
                    f"{b.trajectory_rmse_per_joint[j]:.3g} → {a.trajectory_rmse_per_joint[j]:.3g} "
                    f"({b.trajectory_rmse_per_joint[j] / a.trajectory_rmse_per_joint[j]:.1f}×)"
                )
                if j
                else "-"
            )
            label = f"{eff[0]}:{eff[1]} = {eff[2]:g}"
            print(
                f"| {system} | {label} | {seed} | {rank} | {found} | {err} | {comb} | {jt} |  <!-- {dt:.0f} s -->",
                flush=True,
            )


if __name__ == "__main__":
    main()
