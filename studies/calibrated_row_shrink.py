"""Does L_Iτ's normaliser reward a light rotor on the calibrated rig? Loss evaluations, no training.

On the calibrated rig's free releases (``studies/calibrated_protocol.py``: 64 releases of 1 s,
2048-count encoders, velocities re-estimated offline with zero phase, the residual summed over 10
of DeLaN's Simpson intervals) the rotor's equation holds the rig's cable spring and the rotor's
dry (Coulomb) friction, which a DeLaN cannot express (its potential is periodic, its damping
viscous). This script asks what L_Iτ then rewards, for two rigid-body models:

* (a) the plant's own model without the spring and the Coulomb friction (what a DeLaN can be);
* (b) the plant's full model (both included);
* (c) with the spring and without the Coulomb friction, and (d) the other way round: which of the
  two the loss needs to find the plant's mass matrix.

Per model: the rotor's and the pendulum's shares of Σ‖r‖² and of Σ‖Δp̂‖² at the plant's
parameters; L_Iτ with both normalisers, ``"momentum"`` (Σ‖r‖² / Σ‖Δp̂‖² over both joints together)
and ``"joint_momentum"`` (the same ratio per joint, summed), with the rotor's row of M and its
damping (J1, J1b, the shared Jc, c_alpha) scaled by s; and the lumped parameters ≥ 0 that minimise
each normaliser, reported as M₁₁/M₂₂ at β = 0 (J1 / J2). On free data the residual and the momentum
changes are linear in θ = (J1, J1b, Jc, J2, G, c_alpha, c_beta[, spring, Coulomb]) with no constant
term, so both losses are ratios of quadratic forms in θ, built from one residual evaluation per
parameter and checked against ``integral_loss`` itself. The best θ: log-parameterised (so ≥ 0),
G pinned (the losses do not see the overall scale) and c_beta pinned (the plant's is ~0),
Nelder-Mead from three starts, then BFGS.

The training data are generated as ``reproduce --plant results/calibrated_protocol/diagnosis.json
--sensor experiment`` does (same recipe, seed, plant and sensor) into ``<out>/row_shrink_data``
and reused from there when its manifest matches. Writes ``<out>/row_shrink.json``;
``studies/calibrated_row_shrink_table.py`` writes its table into docs/learning.md.

    python studies/calibrated_row_shrink.py [--out results/calibrated_protocol]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "calibrated_protocol"
PLANT = OUT / "diagnosis.json"
RESULT_NAME = "row_shrink.json"
CACHE_NAME = "row_shrink_data"
SCALES = (0.2, 0.35, 0.5, 0.75, 1.0, 1.5, 2.0)
#: the rotor's row of M (J1, J1b and the coupling Jc it shares with the pendulum) and its damping
ROW = ("J1", "J1b", "Jc", "c_alpha")
#: the lumped parameters the free-release residual is linear in (K multiplies u = 0)
LINEAR = ("J1", "J1b", "Jc", "J2", "G", "c_alpha", "c_beta")
#: the two effects a DeLaN cannot express, each linear in its coefficient
MISSING = ("spring", "coulomb_friction")
NORMALIZERS = ("momentum", "joint_momentum")
MODELS = {
    "no_spring_coulomb": "the plant's model without the cable spring and the rotor's Coulomb friction",
    "full": "the plant's full model",
    "spring_only": "the plant's model with the cable spring, without the rotor's Coulomb friction",
    "coulomb_only": "the plant's model with the rotor's Coulomb friction, without the cable spring",
}
#: which of ``MISSING`` each model keeps
MODEL_EFFECTS = {
    "no_spring_coulomb": (),
    "full": MISSING,
    "spring_only": ("spring",),
    "coulomb_only": ("coulomb_friction",),
}


def config():
    """The protocol's offline-velocity DeLaN L_prop run (``reproduce_offline``)."""
    from furuta_gym.training.reproduce import ReproduceSettings

    return ReproduceSettings(
        systems=("furuta",),
        pairs=(("dln", "prop"),),
        plant=str(PLANT),
        sensor="experiment",
        integral_span=10,
        training_velocities="zero_phase",
        figures=False,
        progress=False,
    )


def _wanted_manifest(cfg) -> dict:
    from furuta_gym.envs import Plant

    plant = json.loads(json.dumps(Plant.load(cfg.plant).to_json()))
    return {"seed": cfg.data_seed, "small": cfg.small, "plant": plant, "sensor_name": cfg.sensor}


def training_releases(cache: Path, cfg) -> tuple[list, dict]:
    """The protocol's 64 training releases (generated into ``cache`` or reused from it), with
    velocities re-estimated offline with zero phase; and the data's manifest."""
    from furuta_gym.data import load_trajectories
    from furuta_gym.envs import Plant
    from furuta_gym.signals import zero_phase_velocity
    from furuta_gym.training.datagen import MujocoGroundTruth, generate
    from furuta_gym.training.reproduce import SENSORS

    folder, wanted = cache / "data" / "furuta", _wanted_manifest(cfg)
    path = folder / "manifest.json"
    meta = json.loads(path.read_text()) if path.exists() else {}
    held = {k: meta.get(k) for k in wanted}
    if held != wanted or not (folder / meta.get("files", {}).get("train", {}).get("path", "-")).exists():
        print(f"generating the protocol's datasets into {folder} ...", flush=True)
        truth = MujocoGroundTruth("furuta", plant=Plant.load(cfg.plant))
        generate(
            "furuta",
            folder,
            seed=cfg.data_seed,
            small=cfg.small,
            sensor=SENSORS[cfg.sensor],
            ground_truth=truth,
            overwrite=True,
        )
        meta = {**json.loads(path.read_text()), **wanted}
        path.write_text(json.dumps(meta, indent=2) + "\n")
    trajs = load_trajectories(folder / meta["files"]["train"]["path"], "furuta")
    return [dataclasses.replace(t, qd=zero_phase_velocity(np.asarray(t.q), t.dt)) for t in trajs], meta


def loss_windows(trajs, tcfg):
    """L_Iτ's windows as training makes them: the recipe's window, odd for Simpson, tiling each
    release (stride window − 1, the last aligned to its end)."""
    from furuta_gym.training import make_windows

    w = min(tcfg.integral_window, min(len(t) for t in trajs))
    w -= tcfg.quadrature == "simpson" and w % 2 == 0
    return make_windows(trajs, w, stride=w - 1, cover_end=True)


def residual_parts(model, windows, rule: str, span: int):
    """Per window, span group and joint: the residual r and the model's momentum changes Δp̂, as
    L_Iτ computes them (public pieces of :func:`~furuta_gym.training.integral_loss`)."""
    import jax

    from furuta_gym.lagrangian import integral_residual, interval_difference, momentum
    from furuta_gym.training.losses import span_sum

    n = model.spec.n_dof

    def one(t, x, u):
        q, qd = x[:, :n], x[:, n:]
        r = span_sum(integral_residual(model, q, qd, u, t[1] - t[0], rule), span)
        p = jax.vmap(lambda q_, qd_: momentum(model, q_, qd_))(q, qd)
        return r, span_sum(interval_difference(p, rule), span)

    r, dp = jax.vmap(one)(windows.t, windows.x, windows.u)
    return np.asarray(r), np.asarray(dp)


def joint_sums(model, windows, rule: str, span: int) -> tuple[np.ndarray, np.ndarray]:
    """Per joint: Σr² and ΣΔp̂² over windows and span groups (what both normalisers divide)."""
    r, dp = residual_parts(model, windows, rule, span)
    return (r**2).sum(axis=(0, 1)), (dp**2).sum(axis=(0, 1))


def losses(r2, p2) -> dict:
    """Both normalisers from per-joint sums."""
    return {"momentum": float(r2.sum() / p2.sum()), "joint_momentum": float((r2 / p2).sum())}


@dataclasses.dataclass(frozen=True)
class Rig:
    """The plant's lumped parameters and memoryless effects, as a model of θ (``names``)."""

    lumped: dict
    effects: dict
    names: tuple

    @classmethod
    def load(cls, path) -> "Rig":
        from furuta_gym.envs import Plant

        plant = Plant.load(path)
        effects = {e.name: e for e in plant.effects if not e.kind.has_memory}
        return cls(dict(plant.lumped), effects, LINEAR + tuple(m for m in MISSING if m in effects))

    def theta(self) -> np.ndarray:
        return np.array([self.lumped[n] for n in LINEAR] + [self.effects[m].coefficient for m in self.names[7:]])

    def model(self, theta):
        from furuta_gym.effects import WithEffects
        from furuta_gym.models import LumpedSystem

        values = {**self.lumped, **dict(zip(LINEAR, map(float, theta[: len(LINEAR)]), strict=True)), "K": 0.0}
        extra = {m: float(c) for m, c in zip(self.names[7:], theta[7:], strict=True)}
        effects = [e for n, e in self.effects.items() if n not in MISSING]
        effects += [dataclasses.replace(self.effects[m], coefficient=c) for m, c in extra.items() if c != 0]
        return WithEffects(LumpedSystem.of("furuta", values), effects)


def quadratic_forms(rig: Rig, windows, rule: str, span: int) -> tuple[np.ndarray, np.ndarray]:
    """Per joint j, A_j and B_j with Σr_j² = θᵀA_jθ and ΣΔp̂_j² = θᵀB_jθ: r and Δp̂ are linear in θ
    (no constant term), so one evaluation per unit θ gives their columns."""

    def parts(theta):
        r, dp = residual_parts(rig.model(theta), windows, rule, span)
        return r.reshape(-1, 2), dp.reshape(-1, 2)

    cols = [parts(e) for e in np.eye(len(rig.names))]
    J, D = np.stack([c[0] for c in cols], -1), np.stack([c[1] for c in cols], -1)  # (N, 2, P)
    r0, p0 = parts(rig.theta())
    err = max(
        np.abs(J @ rig.theta() - r0).max() / np.abs(r0).max(), np.abs(D @ rig.theta() - p0).max() / np.abs(p0).max()
    )
    if err > 1e-9:
        raise AssertionError(f"the residual is not linear in θ (relative error {err:.2g})")
    return np.stack([J[:, j].T @ J[:, j] for j in range(2)]), np.stack([D[:, j].T @ D[:, j] for j in range(2)])


def form_sums(A, B, theta) -> tuple[np.ndarray, np.ndarray]:
    """Per joint Σr² and ΣΔp̂² at θ from the quadratic forms."""
    return np.einsum("p,jpq,q->j", theta, A, theta), np.einsum("p,jpq,q->j", theta, B, theta)


def scaled(rig: Rig, theta, s: float) -> np.ndarray:
    """θ with the rotor's row of M and its damping (``ROW``) scaled by ``s``."""
    out = np.array(theta, float)
    out[[rig.names.index(n) for n in ROW]] *= s
    return out


def shares(r2, p2) -> dict:
    """The rotor's shares of Σr² and ΣΔp̂², and each joint's own ratio Σr²/ΣΔp̂²."""
    return {
        "rotor_share_of_residual": float(r2[0] / r2.sum()),
        "rotor_share_of_momentum_changes": float(p2[0] / p2.sum()),
        "rotor_ratio": float(r2[0] / p2[0]),
        "pendulum_ratio": float(r2[1] / p2[1]),
        "residual_sums": r2.tolist(),
        "momentum_change_sums": p2.tolist(),
    }


def scan(rig: Rig, A, B, theta) -> list[dict]:
    """Both losses with the rotor's row and damping scaled by each s of ``SCALES``."""
    rows = []
    for s in SCALES:
        r2, p2 = form_sums(A, B, scaled(rig, theta, s))
        rows.append({"s": s, **losses(r2, p2), "rotor_share_of_momentum_changes": float(p2[0] / p2.sum())})
    return rows


def best_fit(rig: Rig, A, B, theta0, normalize: str) -> dict:
    """The θ ≥ 0 (each free entry θ0·e^z) of least L_Iτ with ``normalize``; G and c_beta pinned."""
    from scipy.optimize import minimize

    free = [i for i, n in enumerate(rig.names) if theta0[i] != 0 and n not in ("G", "c_beta")]

    def unpack(z):
        th = np.array(theta0, float)
        th[free] = theta0[free] * np.exp(np.clip(z, -30, 30))  # BFGS's line search may step far
        return th

    def objective(z):
        return np.log(losses(*form_sums(A, B, unpack(z)))[normalize])

    runs = []
    for start in (0.0, np.log(0.3), np.log(3.0)):
        opts = dict(maxiter=20000, maxfev=20000, xatol=1e-6, fatol=1e-10)
        o = minimize(objective, np.full(len(free), start), method="Nelder-Mead", options=opts)
        runs.append(minimize(objective, o.x, method="BFGS"))
    th = unpack(min(runs, key=lambda o: o.fun).x)
    i = {n: rig.names.index(n) for n in ("J1", "Jc", "J2")}
    return {
        "theta": dict(zip(rig.names, th.tolist(), strict=True)),
        "ratio_to_plant": {rig.names[k]: float(th[k] / theta0[k]) for k in free},
        **{f"loss_{k}": v for k, v in losses(*form_sums(A, B, th)).items()},
        "M11_over_M22": float(th[i["J1"]] / th[i["J2"]]),
        "M12_over_M22": float(th[i["Jc"]] / th[i["J2"]]),
        "positive_definite": bool(th[i["J1"]] * th[i["J2"]] > th[i["Jc"]] ** 2),
    }


def study_model(rig: Rig, kept: tuple, windows, tcfg) -> dict:
    """Shares at s = 1, the scan and both best fits for the model that keeps the effects ``kept``."""
    from furuta_gym.training import integral_loss

    rule, span = tcfg.quadrature, tcfg.integral_span
    names = LINEAR + tuple(m for m in MISSING if m in kept and m in rig.effects)
    sub = Rig(rig.lumped, rig.effects, names)
    A, B = quadratic_forms(sub, windows, rule, span)
    theta = sub.theta()
    direct = joint_sums(sub.model(theta), windows, rule, span)
    checks = {}
    for s in (0.5, 1.0):
        model = sub.model(scaled(sub, theta, s))
        form = losses(*form_sums(A, B, scaled(sub, theta, s)))
        for n in NORMALIZERS:
            value = float(integral_loss(model, windows, rule=rule, normalize=n, span=span))
            if abs(value - form[n]) > 1e-9 * value:
                raise AssertionError(f"s={s}, {n}: integral_loss {value} ≠ quadratic forms {form[n]}")
            checks[f"s={s}, {n}"] = value
    fits = {n: best_fit(sub, A, B, theta, n) for n in NORMALIZERS}
    return {
        "parameters": list(names),
        "plant_M11_over_M22": float(theta[0] / theta[3]),
        "plant_M12_over_M22": float(theta[2] / theta[3]),
        "at_plant": {**shares(*direct), **losses(*direct)},
        "integral_loss_checks": checks,
        "scan": scan(sub, A, B, theta),
        "best_fit": fits,
    }


def main(argv=None) -> int:
    from furuta_gym.training.reproduce import machine_info, training_settings

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT, help=f"folder of {RESULT_NAME} and of the data cache")
    args = ap.parse_args(argv)
    cfg, t0 = config(), time.perf_counter()
    trajs, meta = training_releases(args.out / CACHE_NAME, cfg)
    tcfg = training_settings("furuta", cfg, 0, "prop", "dln")
    windows = loss_windows(trajs, tcfg)
    rig = Rig.load(cfg.plant)
    doc = {
        "command": " ".join(["python studies/calibrated_row_shrink.py", *(sys.argv[1:] if argv is None else argv)]),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": machine_info(),
        "plant": str(PLANT.relative_to(ROOT)),
        "data": {"seed": meta["seed"], "sensor": meta["sensor_name"], "train_sha256": meta["files"]["train"]["sha256"]},
        "windows": {"count": windows.n_windows, "samples": windows.length},
        "rule": tcfg.quadrature,
        "span": tcfg.integral_span,
        "scaled": list(ROW),
        "models": {key: {"description": text} for key, text in MODELS.items()},
    }
    for key in MODELS:
        doc["models"][key].update(study_model(rig, MODEL_EFFECTS[key], windows, tcfg))
        print(key, json.dumps(doc["models"][key]["at_plant"]), flush=True)
    doc["seconds"] = round(time.perf_counter() - t0, 1)
    path = args.out / RESULT_NAME
    path.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
