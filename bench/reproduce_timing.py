"""Refresh the "Reproduction timings" section of BENCHMARKS.md from reproduction run records.

`furuta-gym reproduce` times itself (data, every model's training + evaluation, figures, total)
and writes ``<out>/run.json``; this script tabulates one or more such records side by side:

    python bench/reproduce_timing.py results/reproduce/run.json [more run.json ...]

It never runs a reproduction itself (a full run takes most of an hour on a shared 2-core CPU).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

START, END = "<!-- reproduce_timing:start -->", "<!-- reproduce_timing:end -->"


def section(records: list[tuple[Path, dict]]) -> str:
    lines = [
        START,
        "## Reproduction timings (`furuta-gym reproduce`)",
        "",
        "Wall-clock seconds from each run's own `run.json` (`python bench/reproduce_timing.py "
        + " ".join(str(p) for p, _ in records)
        + "`). Per model: training (JAX compiles included) + evaluation on every test set. "
        "The machine is shared: the load average at the time is part of the number.",
        "",
        "| run | date (UTC) | machine | command | epochs (stage 1, stage 2; L_prop: L_Iτ alone, stage 1, stage 2) | data s | models | per model s (min / median / max) | all models s (reused: as trained) | figures s | total s |",
        "|---|---|---|---|---|---:|---:|---|---:|---:|---:|",
    ]
    for path, rec in records:
        secs = rec.get("seconds", {})
        per_model = [
            v["seconds"]
            for k, v in secs.items()
            if isinstance(v, dict) and v.get("status") in ("trained", "resumed", "loaded")
        ]
        data_s = sum(v for k, v in secs.items() if k.endswith("/data"))
        # a reused model's record keeps what it cost when it was trained (train + evaluate)
        all_models = sum(
            v["seconds"] if v.get("status") != "reused" else sum((v.get("original") or {}).values())
            for v in secs.values()
            if isinstance(v, dict)
        )
        if per_model:
            per_model.sort()
            stats = f"{per_model[0]:.0f} / {per_model[len(per_model) // 2]:.0f} / {per_model[-1]:.0f}"
        else:
            stats = "all reused"
        epochs = ", ".join(f"{s}: {tuple(e)}" for s, e in rec.get("epochs", {}).items())
        if rec.get("prop_epochs"):  # L_prop runs: (L_Iτ alone, stage 1, stage 2)
            epochs += "; L_prop " + ", ".join(f"{s}: {tuple(e)}" for s, e in rec["prop_epochs"].items())
        for model, e in (rec.get("prop_epochs_by_model") or {}).items():  # a model's own L_prop schedule
            epochs += f"; {model} L_prop: {tuple(e)}"
        machine = rec.get("machine", {})
        cpu = f"{machine.get('cpu', '?')}, {machine.get('cpu_count', '?')} cores"
        lines.append(
            f"| {path.parent.name} | {rec.get('date_utc', '?')} | {cpu} | `{rec.get('command') or '(API)'}` | "
            f"{epochs} | {data_s:.0f} | {len(per_model)} | {stats} | {all_models:.0f} | {secs.get('figures', 0):.0f} | "
            f"{secs.get('total', 0):.0f} |"
        )
    lines += [
        "",
        "Models counts the runs that trained (or resumed, or only evaluated an existing checkpoint: "
        "status `loaded` in run.json, which then times evaluation only); `reused` ones are not timed.",
    ]
    lines += [
        "",
        "Machine: the run record's CPU (the shared machine changed from an AMD EPYC to an Intel Xeon, "
        "both 2 logical cores, between 2026-11-22 and 2026-11-23, and back to an AMD EPYC on "
        "2026-11-25 evening: compare times on one machine only).",
        END,
    ]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        return 2
    records = [(Path(a), json.loads(Path(a).read_text())) for a in argv]
    bench = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
    text = bench.read_text() if bench.exists() else "# Benchmarks\n"
    new = section(records)
    if START in text and END in text:
        text = re.sub(re.escape(START) + ".*?" + re.escape(END), lambda _: new, text, flags=re.S)
    else:
        text = text.rstrip("\n") + "\n\n" + new + "\n"
    bench.write_text(text)
    print(new)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
