"""What a log holds, read before anything is diagnosed or trained on it (``furuta-gym inspect``).

Per log and trajectory: duration, sample rate, gaps, per joint the encoder's quantum and the unit
it implies, range, share of repeated counts, velocity range and reversals, the input's range and
share at its limits; then what the log can and cannot identify. The log is read as every command
reads it (:func:`furuta_gym.data.read_log`), leniently: what would stop a diagnosis is listed
(``problems``), not raised, and the statistics are of the log as it is.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from .data import LogReading, Trajectory
from .lagrangian import SystemSpec
from .measured import estimate_velocities
from .reading import implied_unit, quantum

__all__ = ["SPRING_SPAN", "WANDER", "describe_trajectory", "identifiability", "describe_log", "format_inspection"]

#: A joint that never leaves ± this of its median, rad, shows no spring at all: over so small a
#: span a spring's torque is a constant torque.
SPRING_SPAN = 0.05
#: Distance from its median, rad, beyond which a joint's spring shows; the shipped QUBE runs whose
#: rotor spends time beyond it carry the cable spring (docs/diagnose.md, "Real data"), and a joint
#: that never gets there shows one hardly.
WANDER = 0.5


def _reversals(v: np.ndarray, threshold: float) -> int:
    """Sign changes of a velocity between moving one way and the other by more than ``threshold``."""
    s = np.sign(v) * (np.abs(v) > threshold)
    s = s[s != 0]
    return int(np.sum(s[1:] != s[:-1]))


def describe_trajectory(tr: Trajectory, spec: SystemSpec) -> dict[str, Any]:
    """One trajectory's statistics (JSON-ready)."""
    logged = tr.qd is not None
    tr = estimate_velocities(tr) if len(tr) > 3 else tr
    out: dict[str, Any] = {
        "name": tr.name,
        "samples": len(tr),
        "duration_s": len(tr) * tr.dt,
        "sample_rate_hz": 1.0 / tr.dt,
        "velocities": "logged" if logged else "estimated",
        "joints": {},
    }
    for j, joint in enumerate(spec.joint_names):
        q = tr.q[:, j]
        step = quantum(q)
        unit, per_turn = implied_unit(step, q) if spec.angular[j] else (None, None)
        steps = np.diff(q)
        qd = None if tr.qd is None else tr.qd[:, j]
        out["joints"][joint] = {
            "quantum": step,
            "implied_unit": unit,
            "counts_per_turn": per_turn,
            "range": [float(q.min()), float(q.max())],
            "repeated_share": float(np.mean(steps == 0)) if steps.size else 0.0,
            "velocity_range": None if qd is None else [float(qd.min()), float(qd.max())],
            "reversals": None if qd is None else _reversals(qd, (step or 1e-3) / 0.1),
        }
    u = tr.u[:, 0]
    at_limit = np.isclose(u, u.max()) | np.isclose(u, u.min()) if np.ptp(u) > 0 else np.zeros(u.shape, bool)
    out["input"] = {"range": [float(u.min()), float(u.max())], "saturation_share": float(np.mean(at_limit))}
    return out


def identifiability(trajs: Sequence[Trajectory], spec: SystemSpec) -> tuple[list[str], list[str]]:
    """(what ``trajs`` can identify, what they cannot), pooled, each as one sentence."""
    can, cannot = [], []
    u = np.concatenate([np.asarray(tr.u, float).reshape(len(tr), -1)[:, 0] for tr in trajs])
    if np.ptp(u) == 0:
        name = spec.input_names[0]
        cannot.append(f"{name} = {u[0]:g} throughout: the input gain and the overall scale are not identifiable")
    else:
        can.append("the input varies: the input gain, with one parameter fixed as the scale anchor")
    dt = float(np.median([tr.dt for tr in trajs]))
    for j, joint in enumerate(spec.joint_names):
        _joint_statements(trajs, spec, j, joint, can, cannot)
    cannot.append(f"one sample is {dt * 1e3:.3g} ms: an input delay or lag shorter than that is not resolved")
    return can, cannot


def _joint_statements(trajs, spec: SystemSpec, j: int, joint: str, can: list[str], cannot: list[str]) -> None:
    q = np.concatenate([tr.q[:, j] for tr in trajs])
    unit = spec.joint_units[j]
    step = quantum(np.concatenate([np.append(tr.q[:, j], np.nan) for tr in trajs]))
    if np.ptp(q) <= 5 * (step or 1e-6):
        cannot.append(f"{joint} never moves (range {np.ptp(q):.3g} {unit}): nothing about it is identifiable")
        return
    moved = [estimate_velocities(tr).qd[:, j] for tr in trajs if len(tr) > 3]  # type: ignore[index]
    reversals = sum(_reversals(v, (step or 1e-3) / 0.1) for v in moved)
    if reversals:
        can.append(f"{joint} reverses {reversals} times: its dry (Coulomb) friction, at the reversals")
    else:
        cannot.append(f"{joint} never reverses: its dry friction is a constant torque to these data")
    if not spec.angular[j]:
        return
    spread = np.abs(q - np.median(q))
    far = float(np.mean(spread > WANDER))
    if far == 0:
        cannot.append(
            f"{joint} never goes further than {spread.max():.2g} {unit} from its median: a spring on it can "
            "hardly be told from a constant torque"
            + (" (it cannot be seen at all)" if spread.max() < SPRING_SPAN else "")
        )
    else:
        can.append(
            f"a spring on {joint}, where it wanders: {far:.0%} of the samples are further than {WANDER:g} {unit} "
            "from its median (a spring pulls as hard as the joint is far from its rest)"
        )
    if step is not None:
        cannot.append(
            f"one count of {joint} is {step:.3g} {unit}: an offset under it (a centre of mass, the encoder's zero) "
            "is not resolved"
        )


def _gaps(trajs: Sequence[Trajectory]) -> list[dict[str, float]]:
    """Time missing between consecutive pieces of one trajectory (named ``<name>/<k>``)."""
    out = []
    for a, b in zip(trajs[:-1], trajs[1:], strict=True):
        if "/" in b.name and a.name.rpartition("/")[0] == b.name.rpartition("/")[0]:
            out.append({"after_s": float(a.t[-1]), "missing_s": float(b.t[0] - a.t[-1] - a.dt)})
    return out


def describe_log(source: str, reading: LogReading, spec: SystemSpec) -> dict[str, Any]:
    """One log's inspection (JSON-ready): notes and problems of its reading, gaps, trajectories,
    what it can and cannot identify."""
    trajs = reading.trajectories
    can, cannot = identifiability(trajs, spec)
    return {
        "source": source,
        "notes": list(reading.notes),
        "problems": list(reading.problems),
        "gaps": _gaps(trajs),
        "trajectories": [describe_trajectory(tr, spec) for tr in trajs],
        "identifiable": can,
        "not_identifiable": cannot,
    }


def _joint_line(joint: str, d: dict, unit: str) -> str:
    if d["quantum"] is None:
        quant = "no quantum"
    else:
        implied = d["implied_unit"] or "unit not implied"
        per = f" = 1/{d['counts_per_turn']} turn" if d["counts_per_turn"] else ""
        quant = f"quantum {d['quantum']:.4g}{per} ({implied})"
    lo, hi = d["range"]
    vel = "" if d["velocity_range"] is None else " velocity [{:.3g}, {:.3g}] {}/s,".format(*d["velocity_range"], unit)
    return (
        f"    {joint}: {quant}, range [{lo:.4g}, {hi:.4g}] {unit}, repeated counts {d['repeated_share']:.0%},"
        f"{vel} {d['reversals']} reversals"
    )


def format_inspection(logs: Sequence[dict], spec: SystemSpec, pooled: tuple[list[str], list[str]] | None) -> str:
    """The inspections of ``logs`` as text; ``pooled``: what all of them together can identify."""
    lines = []
    for log in logs:
        lines.append(log["source"])
        lines += [f"  read: {n}" for n in log["notes"]] + [f"  would stop: {p}" for p in log["problems"]]
        gaps = log["gaps"]
        lines.append(
            f"  gaps: {len(gaps)}" + "".join(f"; {g['missing_s']:.4g} s after t = {g['after_s']:.6g}" for g in gaps)
        )
        for tr in log["trajectories"]:
            lines.append(
                f"  {tr['name']}: {tr['duration_s']:.4g} s at {tr['sample_rate_hz']:.4g} Hz ({tr['samples']} samples, "
                f"velocities {tr['velocities']})"
            )
            for j, joint in enumerate(spec.joint_names):
                lines.append(_joint_line(joint, tr["joints"][joint], spec.joint_units[j]))
            lo, hi = tr["input"]["range"]
            lines.append(
                f"    {spec.input_names[0]}: range [{lo:.4g}, {hi:.4g}] {spec.input_units[0]}, "
                f"at its limits {tr['input']['saturation_share']:.1%} of the samples"
            )
        lines += _statements(log["identifiable"], log["not_identifiable"], "  ")
    if pooled is not None:
        lines.append(f"all {len(logs)} logs pooled")
        lines += _statements(*pooled, "  ")
    return "\n".join(lines)


def _statements(can: Sequence[str], cannot: Sequence[str], indent: str) -> list[str]:
    return [f"{indent}can identify: {s}" for s in can] + [f"{indent}cannot: {s}" for s in cannot]
