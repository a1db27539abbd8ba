"""The row-shrink block of docs/learning.md, from ``results/calibrated_protocol/row_shrink.json``
(``studies/calibrated_row_shrink.py``): what L_Iτ's two normalisers reward on the calibrated rig's
training releases, for the plant's model without and with the cable spring and Coulomb friction,
and with each of the two alone.

    python studies/calibrated_row_shrink_table.py [--check]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULT = ROOT / "results" / "calibrated_protocol" / "row_shrink.json"
NORMALIZERS = ("momentum", "joint_momentum")
SHORT = {"no_spring_coulomb": "(a)", "full": "(b)"}  # the scan's models
LABELS = {
    "no_spring_coulomb": "(a) without spring and Coulomb friction",
    "full": "(b) full model",
    "spring_only": "(c) spring, no Coulomb friction",
    "coulomb_only": "(d) Coulomb friction, no spring",
}


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %"


def shares_table(doc: dict) -> list[str]:
    """Per model at the plant's parameters: the rotor's shares and each joint's own ratio."""
    lines = [
        "| model | rotor's share of Σr² | rotor's share of ΣΔp̂² | rotor's Σr²/ΣΔp̂² | pendulum's Σr²/ΣΔp̂² | "
        "L_Iτ, `momentum` | L_Iτ, `joint_momentum` |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for key, m in doc["models"].items():
        p = m["at_plant"]
        lines.append(
            f"| {LABELS[key]} | {_pct(p['rotor_share_of_residual'])} | {_pct(p['rotor_share_of_momentum_changes'])} | "
            f"{p['rotor_ratio']:.3g} | {p['pendulum_ratio']:.2g} | {p['momentum']:.3g} | {p['joint_momentum']:.3g} |"
        )
    return lines


def scan_table(doc: dict) -> list[str]:
    """L_Iτ per s, per model and normaliser; each column's least value in bold."""
    columns = [(key, n) for key in doc["models"] if key in SHORT for n in NORMALIZERS]
    scans = {c: [row[c[1]] for row in doc["models"][c[0]]["scan"]] for c in columns}
    lines = [
        "| s | " + " | ".join(f"{SHORT[k]} `{n}`" for k, n in columns) + " |",
        "|---:|" + "---:|" * len(columns),
    ]
    first = next(iter(doc["models"].values()))["scan"]
    for i, row in enumerate(first):
        cells = []
        for c in columns:
            text = f"{scans[c][i]:#.3g}"
            cells.append(f"**{text}**" if scans[c][i] == min(scans[c]) else text)
        lines.append(f"| {row['s']:g} | " + " | ".join(cells) + " |")
    return lines


def fit_table(doc: dict) -> list[str]:
    """Per model and normaliser: the best θ ≥ 0's mass-matrix ratios, damping and loss."""
    lines = [
        "| model | normaliser | M₁₁/M₂₂ | M₁₂/M₂₂ | J2 / plant's | c_alpha / plant's | L_Iτ at the fit / at the plant |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for key, m in doc["models"].items():
        lines.append(
            f"| {LABELS[key]}, the plant's parameters | — | {m['plant_M11_over_M22']:.2f} | "
            f"{m['plant_M12_over_M22']:.2f} | 1 | 1 | 1 |"
        )
        for n, fit in m["best_fit"].items():
            ratio = fit["ratio_to_plant"]
            lines.append(
                f"| {LABELS[key]} | `{n}` | {fit['M11_over_M22']:.2f} | {fit['M12_over_M22']:.2f} | "
                f"{ratio['J2']:.2f} | {ratio['c_alpha']:.2f} | {fit[f'loss_{n}'] / m['at_plant'][n]:.2f} |"
            )
    return lines


def body() -> str:
    doc = json.loads(RESULT.read_text())
    scaled = ", ".join(doc["scaled"])
    return "\n".join(
        [
            f"L_Iτ on the protocol's {doc['windows']['count']} training releases ({doc['rule'].capitalize()} rule, residual "
            f"summed over {doc['span']} intervals, zero-phase velocities; loss evaluations only, "
            f"`{doc['command']}`, {doc['date']}). At the plant's parameters, per joint:",
            "",
            *shares_table(doc),
            "",
            f"The rotor's row of M and its damping ({scaled}) scaled by s, the rest at the plant's "
            "(each column's least value in bold):",
            "",
            *scan_table(doc),
            "",
            "The lumped parameters ≥ 0 of least L_Iτ under each normaliser (G pinned: the loss does not "
            "see the overall scale; c_beta pinned at the plant's ~0), M at β = 0 (M₁₁/M₂₂ = J1/J2):",
            "",
            *fit_table(doc),
        ]
    )


if __name__ == "__main__":
    sys.exit(block_main(__file__, ROOT / "docs" / "learning.md", "calibrated-row-shrink", body))
