"""How much of the validation and scale-fit data repeats the test sets (issue 25, item 1).

    python studies/validation_overlap.py            # writes results/validation_overlap/
    python studies/validation_overlap.py --table    # rewrite the docs table from the file
    python studies/validation_overlap.py --check    # exit 1 if the docs table and file differ

A sample "repeats" a test set when a test trajectory, at the same time, has a state within
(``same time``, the measure that shows a validation trajectory following a test trajectory under
a shared input) — or when any test sample at any time does (``any time``: coverage of the same
region of state space, which free trajectories of one damped system share whatever their start): Furuta β ± 0.01 rad (modulo 2π), α̇ and β̇ ± 0.1 rad/s (α ignored: the rotor
has a continuum of equilibria); N-MSD p and ṗ within 1 % of the test sets' RMS. Compared:

* the old validation draw (the test recipes generated with seed 100) against the test sets (seed 0);
* the validation datasets of :func:`furuta_gym.training.datagen.generate_validation` (own
  excitation and initial states) against all test sets;
* the scale-fit trajectories (the reproduction's ``scale_fit``; the validation ``val_scale_fit``)
  against all test sets.

Noise-free data from the MuJoCo ground truth (the reproduction's). The table in docs/reproduce.md
is generated from ``results/validation_overlap/overlap.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import furuta_gym  # noqa: F401  first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import fill_block, update  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULT = ROOT / "results" / "validation_overlap" / "overlap.json"
DOCS = ROOT / "docs" / "reproduce.md"
NAME = "validation-overlap"  # the docs/reproduce.md block this writes
OLD_VALIDATION_SEED = 100


def tolerances(system: str, tests: list) -> tuple[list[float], list[bool]]:
    if system == "furuta":
        return [np.inf, 0.01, 0.1, 0.1], [False, True, False, False]
    rms = np.sqrt(np.mean(np.concatenate([tr.x for tr in tests]) ** 2, axis=0))
    return list(0.01 * rms), [False, False]


def measure(system: str) -> list[dict]:
    from furuta_gym.training.datagen import (
        DATASET_NAMES,
        FurutaRecipe,
        generate_datasets,
        generate_validation,
        sample_overlap,
    )

    test = generate_datasets(system, seed=0, ground_truth="mujoco")
    old = generate_datasets(system, seed=OLD_VALIDATION_SEED, ground_truth="mujoco")
    new = generate_validation(system, seed=0, ground_truth="mujoco")
    test_names = [n for n in DATASET_NAMES[system] if n.startswith("test_")]
    all_tests = [tr for n in test_names for tr in test[n]]
    tol, angular = tolerances(system, all_tests)
    rows = []

    def add(kind, name, data, against, reference):
        rows.append(
            {
                "system": system,
                "kind": kind,
                "data": name,
                "against": against,
                "same_time": sample_overlap(data, reference, tol, angular, same_time=True),
                "any_time": sample_overlap(data, reference, tol, angular, same_time=False),
            }
        )

    for n in test_names:  # the old protocol: the same recipe, another seed, against its own test set
        add("old validation (test recipe, seed 100)", n, old[n], n, test[n])
    for n, trajs in new.items():
        add("validation (own excitation)", n, trajs, "all test sets", all_tests)
    if "scale_fit" in test:
        add("scale fit of the reproduction (random steps)", "scale_fit", test["scale_fit"], "all test sets", all_tests)
        chirp = generate_datasets(system, seed=0, ground_truth="mujoco", recipe=FurutaRecipe(scale_fit_input="chirp"))
        add(
            'earlier scale fit, `scale_fit_input="chirp"` (the test chirp)',
            "scale_fit",
            chirp["scale_fit"],
            "all test sets",
            all_tests,
        )
    return rows


def table(rows: list[dict]) -> str:
    lines = [
        "| system | data | compared with | repeating a test sample: same time | any time |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['system']} | {r['kind']}: `{r['data']}` | {r['against']} | "
            f"{100 * r['same_time']:.1f} % | {100 * r['any_time']:.1f} % |"
        )
    return "\n".join(lines)


def documented(rows: list[dict]) -> str:
    """docs/reproduce.md with its overlap block written from ``rows``."""
    return fill_block(DOCS.read_text(), NAME, table(rows), where=DOCS)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--table", action="store_true", help="only rewrite the docs table from the file")
    ap.add_argument("--check", action="store_true", help="exit 1 if docs/reproduce.md is stale")
    args = ap.parse_args(argv)
    if args.check:
        return update(
            DOCS,
            documented(json.loads(RESULT.read_text())["rows"]),
            True,
            "run python studies/validation_overlap.py --table",
        )
    if not args.table:
        import furuta_gym

        furuta_gym.enable_x64()
        rows = measure("furuta") + measure("nmsd")
        RESULT.parent.mkdir(parents=True, exist_ok=True)
        RESULT.write_text(json.dumps({"rows": rows}, indent=1) + "\n")
    rows = json.loads(RESULT.read_text())["rows"]
    print(table(rows))
    return update(DOCS, documented(rows), False, "")


if __name__ == "__main__":
    raise SystemExit(main())
