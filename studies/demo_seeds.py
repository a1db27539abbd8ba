"""Is the demo's physics sentence stable over seeds? Runs ``furuta-gym demo`` at its default
budget for each seed (unless ``results/demo_seeds/seed<k>.json`` exists) and writes the block
``demo-seeds`` of docs/learning.md: per seed, the held-out prediction error and the energy and
force-decomposition errors of DeLaN L_prop and DeLaN L_traj against the truth.

    python studies/demo_seeds.py [--seeds 0,1,2,3,4] [--check]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import fill_block, update  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "demo_seeds"
DOC = ROOT / "docs" / "learning.md"
NAME = "demo-seeds"
DEMO_CHECK = ROOT / "results" / "cpu_numerics" / "demo.json"


def run_seed(seed: int) -> None:
    """The README's demo command at one seed (no video); its summary kept in the results."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "demo"
        subprocess.run(
            [
                sys.executable,
                "-m",
                "furuta_gym",
                "demo",
                "--no-progress",
                "--no-video",
                "--seed",
                str(seed),
                "--out",
                str(out),
            ],
            check=True,
        )
        RESULTS.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(out / "summary.json", RESULTS / f"seed{seed}.json")


def _wins(docs: list[dict], block: str, key: str) -> int:
    """On how many seeds L_prop's error in ``block``/``key`` is the lower."""
    return sum(d[block]["prop"][key] < d[block]["traj"][key] for d in docs)


def _numerics(docs: list[dict]) -> str:
    """Which numerics made the runs (``summary.json``'s ``numerics``), if they all say the same."""
    seen = {(d.get("numerics") or {}).get("xla_flags") for d in docs}
    if len(seen) != 1 or None in seen:
        return "numerics not recorded alike in every run"
    flags = seen.pop()
    if "--xla_cpu_max_isa=AVX2" not in flags:
        return f"native numerics (`XLA_FLAGS={flags}`): other machines may give other numbers"
    return f"with furuta_gym's pinned numerics (`XLA_FLAGS={flags}`); {_other_machines()}"


def _other_machines() -> str:
    """What results/cpu_numerics/demo.json (studies/cpu_numerics.py --demo) shows of other machines."""
    where = 'docs/conventions.md, "Same numbers on every machine"'
    demo = json.loads(DEMO_CHECK.read_text()) if DEMO_CHECK.is_file() else None
    if demo is None or not all(r["digest"] == demo["demo_seeds_row"] for r in demo["rows"]):
        return f"that another machine gives these exact numbers is shown at CI size only, not for the demo ({where})"
    emulated = demo["rows"][-1]["label"]
    return f"the seed-0 run gives the same bits on an emulated {emulated} ({where})"


def block(docs: list[dict]) -> str:
    """The table, each number as the demo's summary prints it (RMSE .3g, log10 .2f)."""
    rows = [
        "| seed | loss | held-out RMSE α / β (rad) | energy log10 | forces log10 | inertial | Coriolis | gravity |",
        "|---|---|---|---|---|---|---|---|",
    ]
    lower, margins = 0, []
    for d in docs:
        margins.append(d["physics"]["traj"]["forces"] - d["physics"]["prop"]["forces"])
        ph, tr = d["physics"], d["tracking"]
        lower += ph["prop"]["forces"] < ph["traj"]["forces"]
        for loss in ("prop", "traj"):
            p = ph[loss]
            rows.append(
                f"| {d['config']['seed']} | L_{loss} | {tr[loss]['rmse_alpha']:.3g} / {tr[loss]['rmse_beta']:.3g} "
                f"| {p['energy']:.2f} | {p['forces']:.2f} | {p['inertial']:.2f} | {p['coriolis']:.2f} "
                f"| {p['potential']:.2f} |"
            )
    epochs = docs[0]["config"]["epochs"]
    return "\n".join(
        [
            f"`furuta-gym demo` at its default budget ({docs[0]['config']['n_train']} free trajectories of 1 s, "
            f"epochs {epochs[0]} + {epochs[1]}), one row per seed and loss; log10 RMSE against the truth on the held-out "
            "states (forces: the mean of the inertial, Coriolis and gravity terms).",
            "",
            *rows,
            "",
            f"Seeds on which L_prop is the closer model, of {len(docs)}: the held-out free run's α "
            f"**{_wins(docs, 'tracking', 'rmse_alpha')}**, its β **{_wins(docs, 'tracking', 'rmse_beta')}**, the force "
            f"decomposition **{lower}** (L_traj's minus L_prop's log10: {', '.join(f'{m:+.2f}' for m in margins)}), "
            f"the energy **{_wins(docs, 'physics', 'energy')}**. The demo's summary names the comparison that held on "
            "every seed here as the stable one and says the others change with the seed (tests/test_demo.py checks "
            "that against these results).",
            "",
            f"Made by `python studies/demo_seeds.py` (results/demo_seeds/), {_numerics(docs)}.",
        ]
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    for seed in seeds:
        if not (RESULTS / f"seed{seed}.json").is_file() and not args.check:
            run_seed(seed)
    docs = [json.loads((RESULTS / f"seed{s}.json").read_text()) for s in seeds]
    text = fill_block(DOC.read_text(), NAME, block(docs), where=DOC)
    return update(DOC, text, args.check, "run python studies/demo_seeds.py")


if __name__ == "__main__":
    sys.exit(main())
