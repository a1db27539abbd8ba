"""Coverage of the diagnosis' 95 % intervals on simulated logs whose truth is known.

Scenarios (``SCENARIOS``), one diagnosis per seed, each log as in tests/test_diagnose.py:

* ``furuta_cable_spring``: the Furuta with an undeclared rotor cable spring of 2e-3 N m/rad,
  random chirps, encoder-quantised angles at 500 Hz;
* ``nmsd_force_and_spring``: the N-MSD with an undeclared constant force of 0.5 N and an extra
  linear spring of 2 N/m (which the declared k1 absorbs: the true k1 is the nominal + 2, so the
  nominal values are not the truth), positions with 1 mm noise at 100 Hz.

For every reported interval (added effects and fitted parameters) the log records the truth, the
estimate, the interval, whether it holds the truth, and the same for mujoco.sysid's iid interval
s²(JᵀJ)⁻¹ for comparison; an effect the diagnosis did not add counts as a miss. Writes
``results/diagnose_intervals/coverage.json`` (per log and per scenario and parameter).

    python studies/diagnose_intervals.py [--logs 25] [--scenario NAME ...]

The slow test (tests/test_diagnose_intervals.py) runs the same logs and asserts what this
records: each added effect's interval holds the truth on ≥ 90 % of the logs, and so do the
parameters' intervals (each parameter given one on ≥ 20 logs, and all of them pooled).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

from furuta_gym.diagnose import diagnose, nominal_base  # noqa: E402
from furuta_gym.effects import Effect  # noqa: E402
from furuta_gym.rigs import measured_like  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "diagnose_intervals"
LOGS = 25  # seeds 0..LOGS-1 per scenario

SCENARIOS = {
    "furuta_cable_spring": dict(
        system="furuta",
        effects=[Effect("spring", "alpha", 2e-3)],
        log=dict(n_trajectories=6, duration=5.0),
        absorbed={},
    ),
    "nmsd_force_and_spring": dict(
        system="nmsd",
        effects=[Effect("constant_torque", "p", 0.5), Effect("spring", "p", 2.0)],
        log=dict(n_trajectories=6, duration=8.0),
        absorbed={"spring:p": "k1"},
    ),
}


def truths(scenario: dict) -> tuple[dict[str, float], dict[str, float]]:
    """({base parameter: true value}, {added effect key: true coefficient}); an effect the
    declared model absorbs (``absorbed``) shifts its base parameter instead."""
    base = dict(nominal_base(scenario["system"]))
    effects = {}
    for e in scenario["effects"]:
        key = f"{e.name}:{e.joint}"
        if key in scenario["absorbed"]:
            base[scenario["absorbed"][key]] += e.coefficient
        else:
            effects[key] = e.coefficient
    return base, effects


def _row(seed, key, truth, estimate, interval) -> dict:
    row = {
        "seed": seed,
        "key": key,
        "truth": truth,
        "estimate": estimate,
        "interval": None,
        "covered": False,
        "iid_covered": None,
        "source": None,
    }
    if interval is not None:
        half = 0.5 * (interval.upper - interval.lower)
        row.update(
            interval=interval.to_json(),
            covered=interval.contains(truth),
            source=interval.source,
            half_width=None if interval.unbounded else half,
            iid_half_width=interval.iid_half_width,
            iid_covered=bool(abs(estimate - truth) <= interval.iid_half_width),
        )
    return row


def run_log(name: str, seed: int) -> list[dict]:
    """One simulated log diagnosed: a row per true effect and per base parameter with an interval."""
    sc = SCENARIOS[name]
    res = diagnose(measured_like(sc["system"], sc["effects"], seed=seed, **sc["log"]), sc["system"])
    base, effects = truths(sc)
    found = {f"{e.name}:{e.joint}": e for e in res.significant}
    rows = [
        _row(
            seed, k, v, None if k not in found else found[k].coefficient, None if k not in found else found[k].interval
        )
        for k, v in effects.items()
    ]
    rows += [_row(seed, k, base[k], res.parameters_after[k], iv) for k, iv in res.intervals.items() if iv is not None]
    return rows


def summary(rows: list[dict]) -> dict:
    """Per key: logs, coverage of the 95 % interval (and of the iid one), median half-widths."""
    out = {}
    for key in dict.fromkeys(r["key"] for r in rows):
        rs = [r for r in rows if r["key"] == key]
        with_iv = [r for r in rs if r["interval"] is not None and r["half_width"] is not None]
        ratio = [r["half_width"] / r["iid_half_width"] for r in with_iv if r["iid_half_width"] > 0]
        out[key] = {
            "logs": len(rs),
            "with_interval": len(with_iv),
            "covered": sum(r["covered"] for r in rs),
            "coverage": sum(r["covered"] for r in rs) / len(rs),
            "iid_coverage": sum(bool(r["iid_covered"]) for r in rs) / len(rs),
            "median_half_width": float(np.median([r["half_width"] for r in with_iv])) if with_iv else None,
            "median_width_over_iid": float(np.median(ratio)) if ratio else None,
            "sources": sorted({r["source"] for r in with_iv}),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=LOGS)
    ap.add_argument("--scenario", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--out", type=Path, default=OUT / "coverage.json")
    args = ap.parse_args()
    doc = {"level": 0.95, "logs_per_scenario": args.logs, "scenarios": {}}
    for name in args.scenario:
        t0, rows = time.perf_counter(), []
        for seed in range(args.logs):
            rows += run_log(name, seed)
        sc = SCENARIOS[name]
        doc["scenarios"][name] = {
            "system": sc["system"],
            "effects": [{"name": e.name, "joint": e.joint, "coefficient": e.coefficient} for e in sc["effects"]],
            "log": sc["log"],
            "seconds": round(time.perf_counter() - t0, 1),
            "summary": summary(rows),
            "rows": rows,
        }
        print(name, json.dumps(doc["scenarios"][name]["summary"], indent=1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
