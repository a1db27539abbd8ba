"""Refresh the "Reproduction timings" section of BENCHMARKS.md from reproduction run records.

`furuta-gym reproduce` times itself (data, every model's training + evaluation, figures, total)
and writes ``<out>/run.json``; this script tabulates one or more such records side by side:

    python bench/reproduce_timing.py results/reproduce/run.json [more run.json ...]

and, with ``--before BEFORE.json --after AFTER.json`` (two full runs of the same command by two
versions of the code, one after the other on one machine), every model's time in both and
their ratio, in a section of its own:

    python bench/reproduce_timing.py --before results/training_speed/before/run.json \
        --after results/training_speed/after/run.json

It never runs a reproduction itself (a full run takes most of an hour on a shared 2-core CPU).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from _generated import fill_section  # bench/'s one writer of generated sections

START, END = "<!-- reproduce_timing:start -->", "<!-- reproduce_timing:end -->"
SIDE_START, SIDE_END = "<!-- reproduce_speedup:start -->", "<!-- reproduce_speedup:end -->"


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


def _model_seconds(rec: dict) -> dict[str, float]:
    """Training + evaluation seconds of every model the run trained itself."""
    return {
        k: v["seconds"]
        for k, v in rec.get("seconds", {}).items()
        if isinstance(v, dict) and v.get("status") == "trained"
    }


def _label(path: Path, rec: dict) -> str:
    """The code version a run record was made by (``label.txt`` beside it, else the package's)."""
    label = path.parent / "label.txt"
    text = label.read_text().strip() if label.exists() else rec.get("furuta_gym_version", "?")
    return f"{text}; run.json of {rec.get('date_utc', '?')}"


def _command(rec: dict) -> str:
    """The command without its output folder (the two runs wrote to two folders)."""
    words = (rec.get("command") or "(API)").split()
    if "--out" in words:
        i = words.index("--out")
        words = words[:i] + words[i + 2 :]
    return " ".join(words)


def side_by_side(before: tuple[Path, dict], after: tuple[Path, dict]) -> str:
    """Every model's seconds in two runs of one command and the ratio before / after."""
    (pb, rb), (pa, ra) = before, after
    if _command(rb) != _command(ra) or rb.get("prop_epochs_by_model") != ra.get("prop_epochs_by_model"):
        raise SystemExit(f"{pb} and {pa} ran other schedules: not a side-by-side comparison")
    tb, ta = _model_seconds(rb), _model_seconds(ra)
    lines = [
        SIDE_START,
        "### Every model before and after (`bench/reproduce_timing.py --before … --after …`)",
        "",
        f"Two full runs from scratch (empty caches) of `{_command(ra)}` on one machine, one after the other: "
        f"before `{pb}` ({_label(pb, rb)}), after `{pa}` ({_label(pa, ra)}). Seconds per model: training, "
        "JAX compiles included, and evaluation on every test set; both runs train two models at a time.",
        "",
        "| model | before s | after s | before / after |",
        "|---|---:|---:|---:|",
    ]
    for model in sorted(tb.keys() & ta.keys()):
        lines.append(f"| {model} | {tb[model]:.0f} | {ta[model]:.0f} | {tb[model] / ta[model]:.2f}× |")
    sb, sa = rb.get("seconds", {}).get("total", 0.0), ra.get("seconds", {}).get("total", 0.0)
    if sa:
        lines.append(f"| **whole run (wall)** | {sb:.0f} | {sa:.0f} | {sb / sa:.2f}× |")
    lines.append(SIDE_END)
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    pair = {}
    for flag in ("--before", "--after"):
        if flag in argv:
            i = argv.index(flag)
            pair[flag] = Path(argv[i + 1])
            argv = argv[:i] + argv[i + 2 :]
    if not argv and len(pair) != 2:
        print(__doc__)
        return 2
    bench = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
    text = bench.read_text() if bench.exists() else "# Benchmarks\n"
    if argv:
        new = section([(Path(a), json.loads(Path(a).read_text())) for a in argv])
        text = fill_section(text, new, START, END)
        print(new)
    if len(pair) == 2:
        before, after = ((p, json.loads(p.read_text())) for p in (pair["--before"], pair["--after"]))
        new = side_by_side(before, after)
        text = fill_section(text, new, SIDE_START, SIDE_END)
        print(new)
    bench.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
