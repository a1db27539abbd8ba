"""The docs table of ``studies/free_releases.py``, generated from its result files.

Reads ``results/free_releases/<variant>_s<seed>.json`` and rewrites the block between
``<!-- generated:free-releases -->`` and ``<!-- /generated:free-releases -->`` in
docs/learning.md: per variant, over its seeds, the learned free frequency against the plant's, how
many seeds learned upright as a maximum, the open-loop 0.5 s angle RMSE on the test release and
its ratio to the L_traj baseline's on the same seed, the coupling M12/M11 at hanging against the
plant's, and the training time. ``--check`` only compares (exit 1 when the docs disagree).

    python studies/free_releases_table.py [--check]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import fill_block, script_command, update  # noqa: E402
from free_releases import VARIANTS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "free_releases"
DOC = ROOT / "docs" / "learning.md"
#: the docs block of each rig
BLOCKS = {"nominal": "free-releases", "calibrated": "free-releases-calibrated"}


def load(folder: Path = RESULTS, rig: str | None = None) -> dict[str, dict[int, dict]]:
    """Result documents per variant (in :data:`VARIANTS`' order) and seed, of one ``rig`` or all."""
    docs: dict[str, dict[int, dict]] = {}
    for path in sorted(folder.glob("*_s*.json")):
        doc = json.loads(path.read_text())
        if rig is None or doc.get("rig", "nominal") == rig:
            docs.setdefault(doc["variant"], {})[doc["seed"]] = doc
    return {v: docs[v] for v in VARIANTS if v in docs}


def _span(values, fmt="{:.0f}") -> str:
    values = sorted(values)
    mid = fmt.format(float(np.median(values)))
    return mid if len(values) == 1 else f"{mid} ({fmt.format(values[0])}–{fmt.format(values[-1])})"


#: the seeds a choice was made on; later seeds are rows of their own, held out from that choice
CHOICE_SEEDS = (0, 1, 2)


def _row(name: str, runs: dict[int, dict], baseline: dict[int, dict], held_out: bool = False) -> str:
    """One variant's line; ``baseline``: its L_traj row's runs by seed."""
    m = {s: d["model"] for s, d in runs.items()}
    freq = _span([100 * r["frequency_error"] for r in m.values()], "{:+.0f}") + " %"
    upright = f"{sum(r['upright_maximum'] for r in m.values())} of {len(m)}"
    rmse = _span([1e3 * r["angle_rmse_rad"] for r in m.values()])
    ratios = [m[s]["angle_rmse_rad"] / baseline[s]["model"]["angle_rmse_rad"] for s in m if s in baseline]
    ratio = _span(ratios, "{:.2g}") + "×" if ratios else "—"
    coupling = _span([r["coupling_ratio_at_hanging"] for r in m.values()], "{:.2f}")
    seconds = _span([d["train_seconds"] for d in runs.values()])
    label = VARIANTS[name].label + (f", held-out seeds {min(runs)}–{max(runs)}" if held_out else "")
    return (
        f"| {label} (`{name}`) | {freq} | {upright} | {rmse} | {ratio} (`{VARIANTS[name].baseline}`) "
        f"| {coupling} | {seconds} |"
    )


def body(rig: str = "nominal", folder: Path = RESULTS) -> str:
    docs = load(folder, rig)
    any_doc = next(iter(next(iter(docs.values())).values()))
    plant_f = any_doc["plant_free_frequency_hz"]
    first = next(iter(docs))  # the rig's first row: the rotor a real one's
    nominal = [1e3 * d["nominal"]["angle_rmse_rad"] for d in docs[first].values()]
    seeds = sorted({s for runs in docs.values() for s in runs if s in CHOICE_SEEDS})
    lines = [
        f"Seeds {', '.join(map(str, seeds))}; median (range) over seeds. The plant's free frequency "
        f"(rotor free, hanging) is {plant_f:.2f} Hz and its coupling M12/M11 at hanging "
        f"{any_doc['nominal']['coupling_ratio_at_hanging']:.2f}; the plant's own rigid-body model, "
        f"without the rotor's friction and cable, predicts the test windows to {_span(nominal)} mrad.",
        "",
        "| variant | free frequency vs plant | upright a maximum | open loop 0.5 s, angle RMSE (mrad) "
        "| × its L_traj (same seed) | coupling M12/M11 | training (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, runs in docs.items():
        baseline = docs.get(VARIANTS[name].baseline, {})
        chosen = {k: d for k, d in runs.items() if k in CHOICE_SEEDS}
        later = {k: d for k, d in runs.items() if k not in CHOICE_SEEDS}
        lines += [_row(name, chosen, baseline)] if chosen else []
        lines += [_row(name, later, baseline, held_out=True)] if later else []
    machines = sorted({d.get("machine", "?") for runs in docs.values() for d in runs.values()})
    lines += [
        "",
        f"Made on {', '.join(machines)} (2 cores, shared with other jobs: times are under load) by `python studies/free_releases.py && python studies/free_releases_table.py`.",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    """Rewrite both rigs' blocks, or with ``--check`` only compare (exit 1 if either is stale)."""
    check = "--check" in (argv if argv is not None else sys.argv[1:])
    text = DOC.read_text()
    for rig, name in BLOCKS.items():
        text = fill_block(text, name, body(rig), where=DOC)
    return update(DOC, text, check, script_command(__file__))


if __name__ == "__main__":
    raise SystemExit(main())
