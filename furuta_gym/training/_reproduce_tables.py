"""The tables of a reproduction run: the paper's cells (shipped as ``paper_tables.csv``), ours
aggregated over seeds beside them, and ``tables.csv`` / ``tables.md`` with the main claim's
summary; part of :mod:`.reproduce`."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..models import model_kind, system_definition
from ._labels import LOSS_LABELS, MODEL_LABELS
from ._reproduce_settings import EVALUATION_SETS, FAILED, METRIC_COLUMNS, PHYSICS_METRICS, ReproduceSettings
from .datagen import system_data
from .loss_kinds import PROPOSED_LOSS, loss_kind

# The paper's result tables, shipped with the package.
_PAPER_CSV_CANDIDATES = (Path(__file__).resolve().parent / "paper_tables.csv",)


def load_paper_table(path: str | Path | None = None) -> dict[tuple[str, str, str, str, str], str]:
    """The paper's cells ``{(system, test_set, MODEL, loss, metric): "value" | "N/A" | "X"}``.

    Reads the copy of the paper's tables shipped beside this module.
    """
    candidates = [Path(path)] if path is not None else list(_PAPER_CSV_CANDIDATES)
    for p in candidates:
        if p.is_file():
            table = {}
            with p.open() as fh:
                lines = [ln for ln in fh if ln.strip() and not ln.startswith("#")]
            header = [h.strip() for h in lines[0].split(",")]
            for ln in lines[1:]:
                cells = [c.strip() for c in ln.split(",")]
                if len(cells) != len(header):  # zip would drop or pad silently
                    raise ValueError(f"{p}: {len(cells)} cells where the header has {len(header)}: {ln.strip()!r}")
                row = dict(zip(header, cells, strict=True))
                key = (row["system"], row["test_set"], row["model"], row["loss"], row["metric"])
                table[key] = row["log10_rmse"]
            return table
    raise FileNotFoundError(f"paper table not found; looked in {[str(c) for c in candidates]}")


def _aggregate(values: Sequence[Any]) -> tuple[str, float | None, float | None, int]:
    """(cell text, mean, std, n diverged or failed) over seeds."""
    diverged = sum(1 for v in values if v == "X")
    failed = sum(1 for v in values if v == FAILED)
    finite = [float(v) for v in values if v not in ("X", FAILED, None)]
    n = len(values)
    if not finite:
        text = "X" if diverged else (FAILED if failed else "N/A")
        return text, None, None, diverged + failed
    mean = float(np.mean(finite))
    std = float(np.std(finite, ddof=1)) if len(finite) > 1 else None
    text = f"{mean:.4f}" if std is None else f"{mean:.2f} ± {std:.2f}"
    if diverged:
        text += f" ({diverged}/{n} X)"
    if failed:
        text += f" ({failed}/{n} {FAILED})"
    return text, mean, std, diverged + failed


def build_tables(results: dict[tuple, list], config: ReproduceSettings) -> list[dict]:
    """One row per (system, test set, model, loss, metric): ours (text, mean, std) and paper."""
    paper = load_paper_table() if config.split == "test" else {}  # no paper value for validation
    rows = []
    for system in config.systems:
        for label in EVALUATION_SETS[config.split][system]:
            for kind, loss in config.pairs:
                per_seed = results.get((system, kind, loss), [])
                for metric in METRIC_COLUMNS[system]:
                    paper_value = paper.get(
                        (system, label, MODEL_LABELS[kind], loss, _paper_metric(metric, config)), ""
                    )
                    values = []
                    if model_kind(kind).analytic_prior and metric in PHYSICS_METRICS:
                        ours_text, mean, std, ndiv = "N/A", None, None, 0
                    else:
                        values = [m[label].get(metric) for m in per_seed]
                        values = [float(v) if isinstance(v, str) and v not in ("X", FAILED) else v for v in values]
                        ours_text, mean, std, ndiv = _aggregate(values)
                    rows.append(
                        dict(
                            system=system,
                            test_set=label,
                            model=MODEL_LABELS[kind],
                            loss=loss,
                            metric=metric,
                            ours=ours_text,
                            ours_mean="" if mean is None else f"{mean:.4f}",
                            ours_std="" if std is None else f"{std:.4f}",
                            n_seeds=len(per_seed),
                            # each seed's own value, in the order of config.seeds: the spread's source
                            ours_per_seed=" ".join(_seed_text(v) for v in values),
                            n_diverged=ndiv,
                            paper=paper_value,
                            better_or_equal=_compare(mean, ours_text, paper_value),
                        )
                    )
    return rows


def _paper_metric(metric: str, config: ReproduceSettings) -> str:
    """The paper's column for ``metric``: on a plant (a calibrated rig), a state's error sits beside
    the paper's experimental column (``exp_<state>``); physics columns have no experimental value."""
    if config.plant is None:
        return metric
    return "" if metric in PHYSICS_METRICS else f"exp_{metric}"


def _seed_text(value) -> str:
    """One seed's cell in ``ours_per_seed``: the number, or X / fail / N/A."""
    if value is None:
        return "N/A"
    return value if isinstance(value, str) else f"{value:.4f}"


def _compare(mean, ours_text, paper_value) -> str:
    """ "yes"/"no" when both cells are numbers (lower is better), "" otherwise."""
    try:
        p = float(paper_value)
    except (TypeError, ValueError):
        return ""
    if mean is None or not math.isfinite(mean) or "X" in ours_text or FAILED in ours_text:
        return "no" if ours_text.startswith(("X", FAILED)) else ""
    return "yes" if mean <= p else "no"


def _write_csv(path: Path, rows: list[dict]) -> Path:

    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return path


_METRIC_HEADERS = {
    "p": "p",
    "p_dot": "ṗ",
    "alpha": "α",
    "beta": "β",
    "alpha_dot": "α̇",
    "beta_dot": "β̇",
    "inertial": "Inertial",
    "coriolis": "Coriolis",
    "potential": "Potential-derived",
    "energy": "Energy",
}


def _write_markdown(path: Path, rows: list[dict], config: ReproduceSettings, data_meta) -> Path:

    lines = [
        "# Reproduction of Tables 1 and 2 (simulated systems)",
        "",
        "log10 RMSE, lower is better. Each cell: **ours** (paper). N/A: given by the APHYNITY prior "
        "(as in the paper); X: the prediction diverged on at least one test trajectory; fail: "
        "training produced no finite model (reason in the run's metrics.json). "
        + (
            f"Ours: mean ± sample standard deviation over {len(config.seeds)} model-initialisation "
            f"seeds ({', '.join(map(str, config.seeds))}; each seed's value is in tables.csv, "
            "ours_per_seed); the data are the same for every seed."
            if len(config.seeds) > 1
            else f"Ours: one model seed ({', '.join(map(str, config.seeds))})."
        )
        + " A ✓ marks our cell at or below the paper's.",
        "",
    ]
    if config.quick:
        lines += [
            "> **Quick run**: scaled-down data and a few epochs — checks the pipeline, not the paper's numbers.",
            "",
        ]
    for system in config.systems:
        cols = METRIC_COLUMNS[system]
        title = system_definition(system).table_title
        gt = data_meta.get(system, {}).get("ground_truth")
        lines += [f"## {title}", "", f"Data: {gt} ground truth, seed {config.data_seed}.", ""]
        lines.append("| Test set | Model | " + " | ".join(_METRIC_HEADERS[c] for c in cols) + " |")
        lines.append("|---|---|" + "---|" * len(cols))
        for label in EVALUATION_SETS[config.split][system]:
            for kind, loss in config.pairs:
                cells = []
                for c in cols:
                    r = next(
                        r
                        for r in rows
                        if (r["system"], r["test_set"], r["model"], r["loss"], r["metric"])
                        == (system, label, MODEL_LABELS[kind], loss, c)
                    )
                    mark = " ✓" if r["better_or_equal"] == "yes" else ""
                    paper = r["paper"] or "–"
                    cells.append(f"**{r['ours']}**{mark} ({paper})")
                lines.append(f"| {label} | {MODEL_LABELS[kind]} ({LOSS_LABELS[loss]}) | " + " | ".join(cells) + " |")
        lines.append("")
    lines += _summary_lines(rows, config)
    path.write_text("\n".join(lines) + "\n")
    return path


def _summary_lines(rows: list[dict], config: ReproduceSettings) -> list[str]:
    out = ["## Summary", ""]
    prop = [r for r in rows if loss_kind(r["loss"]).proposed and r["better_or_equal"] in ("yes", "no")]
    if prop:
        n_yes = sum(r["better_or_equal"] == "yes" for r in prop)
        out.append(f"- L_prop rows: {n_yes} of {len(prop)} numeric cells at or below the paper's.")
    allnum = [r for r in rows if r["better_or_equal"] in ("yes", "no")]
    if allnum:
        n_yes = sum(r["better_or_equal"] == "yes" for r in allnum)
        out.append(f"- All rows: {n_yes} of {len(allnum)} numeric cells at or below the paper's.")
    for system in config.systems:
        out += _main_claim_lines(rows, config, system)
    out.append("")
    return out


def _main_claim_lines(rows: list[dict], config: ReproduceSettings, system: str) -> list[str]:
    """The summary's lines on ``system``'s main claim, metric by metric (none without a claim)."""
    claim = system_data(system).main_claim
    if claim is None:
        return []
    out = [
        f"- Main claim ({claim}: L_prop gives a better force decomposition than L_traj for "
        "DLN and than L_aph for ADLN), ours:"
    ]
    for model, base in (("DLN", "traj"), ("ADLN", "aph")):
        if ((model.lower(), base) not in config.pairs) or ((model.lower(), PROPOSED_LOSS) not in config.pairs):
            continue
        for label in EVALUATION_SETS[config.split][system]:
            parts = [
                _claim_part(
                    _row_of(rows, system, label, model, PROPOSED_LOSS, metric),
                    _row_of(rows, system, label, model, base, metric),
                    metric,
                )
                for metric in ("inertial", "coriolis", "potential")
            ]
            out.append(f"  - {model} {label}: " + "; ".join(parts))
    return out


def _row_of(rows: list[dict], system, label, model, loss, metric) -> Any:
    """The row (a dict) of this cell, or None."""
    return next(
        (
            r
            for r in rows
            if (r["system"], r["test_set"], r["model"], r["loss"], r["metric"]) == (system, label, model, loss, metric)
        ),
        None,
    )


def _claim_part(prop_row, base_row, metric: str) -> str:
    """One metric of a main-claim line: L_prop's mean against the baseline's, and on how many seeds it holds."""
    a, b = _mean_of(prop_row), _mean_of(base_row)
    if a is None or b is None:
        return f"{metric}: n/a"
    seeds = _seeds_holding(prop_row, base_row)
    return f"{metric} {a:.2f} vs {b:.2f} ({'holds' if a < b else 'does not hold'}{seeds})"


def _mean_of(row) -> float | None:
    return float(row["ours_mean"]) if row and row["ours_mean"] else None


def _seeds_holding(prop_row: dict, base_row: dict) -> str:
    """With several seeds, on how many the claim holds seed by seed (seed k of L_prop against
    seed k of the baseline): a mean can hold on one lucky seed."""
    prop, base = prop_row["ours_per_seed"].split(), base_row["ours_per_seed"].split()
    if len(prop) < 2 or len(prop) != len(base):  # seed k against seed k needs the same seeds on both rows
        return ""
    pairs = list(zip(prop, base, strict=True))
    numeric = [(float(a), float(b)) for a, b in pairs if _is_number(a) and _is_number(b)]
    return f"; on {sum(a < b for a, b in numeric)} of {len(pairs)} seeds"


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
