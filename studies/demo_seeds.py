"""Is the demo's physics sentence stable over seeds? Runs ``furuta-gym demo`` at its default
budget for each seed (unless ``results/demo_seeds/seed<k>.json`` exists) and writes the block
``demo-seeds`` of docs/learning.md: per seed, the held-out prediction error and the energy and
force-decomposition errors of DeLaN L_prop and DeLaN L_traj against the truth.

    python studies/demo_seeds.py [--seeds 0,1,2] [--check]
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


def block(docs: list[dict]) -> str:
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
                f"| {d['config']['seed']} | L_{loss} | {tr[loss]['rmse_alpha']:.3f} / {tr[loss]['rmse_beta']:.3f} "
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
            f"L_prop's force decomposition is the closer one on **{lower} of {len(docs)}** seeds (L_traj's minus "
            f"L_prop's log10: {', '.join(f'{m:+.2f}' for m in margins)}; small margins at this budget); its energy on "
            f"{sum(d['physics']['prop']['energy'] < d['physics']['traj']['energy'] for d in docs)} of {len(docs)}.",
            "",
            "Made by `python studies/demo_seeds.py` (results/demo_seeds/).",
        ]
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2")
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
