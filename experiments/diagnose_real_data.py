"""The diagnosis on real QUBE-Servo logs (the 15 MIT runs shipped in ``furuta_gym.datasets``).

Fit on one set of runs, judge on runs never used for fitting; the same on independent sets; and
on growing sets (more runs must never give a weaker answer). Settings are the documented recipe
for these logs (0.5 s start transient dropped, 0.1 s open-loop windows for an inverted pendulum,
64 output-error windows); no threshold is chosen here. Writes one JSON per run of ``diagnose``
into ``results/diagnose_real/`` (the figures and docs tables are generated from them by
``experiments/diagnose_tables.py``).

    python experiments/diagnose_real_data.py [--out results/diagnose_real]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import furuta_gym

furuta_gym.enable_x64()

from furuta_gym.datasets import load_qube_closed_loop  # noqa: E402
from furuta_gym.diagnose import diagnose  # noqa: E402

SETTINGS = dict(window=0.1, oe_max_windows=64)
ALL = list(range(1, 16))
# independent sets of consecutive runs, each judged on the ten it never saw
SPLITS = {"runs01-05": list(range(1, 6)), "runs06-10": list(range(6, 11)), "runs11-15": list(range(11, 16))}
# growing sets from the first run on: a finding must not fade as runs are added
GROWING = {"runs01-03": [1, 2, 3], "runs01-05": list(range(1, 6)), "runs01-10": list(range(1, 11)),
           "runs01-15": ALL}


def run_one(name: str, fit_runs: list[int], test_runs: list[int] | None, out: Path) -> dict:
    target = out / f"{name}.json"
    if target.exists():
        return json.loads(target.read_text())
    t0 = time.time()
    res = diagnose(load_qube_closed_loop(fit_runs), "furuta",
                   test=load_qube_closed_loop(test_runs) if test_runs else None, **SETTINGS)
    doc = res.to_json()
    doc["fit_runs"], doc["test_runs"] = fit_runs, test_runs or []
    doc["seconds"] = round(time.time() - t0, 1)
    doc["machine"] = f"{platform.node()} {platform.processor() or platform.machine()}"
    doc["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    target.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"{name}: {res.table().splitlines()[3:8]}", flush=True)
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/diagnose_real")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, runs in SPLITS.items():
        run_one(f"split_{name}", runs, [r for r in ALL if r not in runs], out)
    for name, runs in GROWING.items():
        rest = [r for r in ALL if r not in runs]
        run_one(f"growing_{name}", runs, rest or None, out)


if __name__ == "__main__":
    main()
