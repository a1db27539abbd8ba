"""The paper's loss on free releases like a real QUBE's (issue 65): what makes L_prop learn wrong
free dynamics, by ablation over seeds.

The data are the paper's experimental kind, as a user records them on a real rig: the pendulum
released at 0 V near upright with the arm free (8 s, cut into eight 1 s trajectories for
training), a second release from about 90° for testing (6 s), and a 0.75 V open-loop sine sweep
(10 s) for the overall scale; 500 Hz, 2048-count encoders, angles only (velocities estimated
zero-phase, as ``furuta-gym train`` does). The plant is MuJoCo with a rotor like the real one
(issue 64): sliding friction 1e-4–3e-4 N·m with a breakaway ten times that, and a cable whose rest
moves (``hysteretic_spring``, k 1.5e-3–2.5e-3 N·m/rad, play 0.1–0.8 rad).

Each variant changes one thing against the ``base`` row (the plant, the sensor, the amount of
data, the quadrature and span, the budget, the loss's options) and is trained on three seeds
(data and weights drawn from the seed). Scored on the test release: the learned free
small-oscillation frequency against the plant's, the potential's curvature at hanging and
upright, and open-loop 0.5 s windows from the measured state (u = 0), angle RMSE.

    python studies/free_releases.py [--variants base,no_friction,...] [--seeds 0,1,2]

writes ``results/free_releases/<variant>_s<seed>.json``; ``studies/free_releases_table.py``
writes the table into docs/learning.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time
import warnings
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import jax.numpy as jnp
import numpy as np

furuta_gym.enable_x64()

from furuta_gym.data import Trajectory  # noqa: E402
from furuta_gym.diagnose import LumpedModel, layout_for  # noqa: E402
from furuta_gym.effects import Effect  # noqa: E402
from furuta_gym.envs import MujocoBackend, Plant  # noqa: E402
from furuta_gym.measured import prepare_log, window_errors  # noqa: E402
from furuta_gym.models import Furuta  # noqa: E402
from furuta_gym.signals import quantize_encoder  # noqa: E402
from furuta_gym.training import TrainSettings, check_potential_shape, fit_scale, train  # noqa: E402
from furuta_gym.training.free_dynamics import model_frequencies  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "free_releases"
DT = 0.002
SUBSTEPS = 10
WINDOW = 0.5
CALIBRATED = ROOT / "results" / "calibrated_protocol" / "diagnosis.json"


@dataclasses.dataclass(frozen=True)
class Variant:
    """One row of the ablation: what differs from the base recipe."""

    name: str
    label: str
    rig: str = "nominal"  # the rigid body: "nominal" (datasheet) or "calibrated" (fitted on the real runs)
    rotor: str = "real"  # "real" (breakaway 10x + moving-rest cable), "none" (no dry friction, no cable)
    quantize: bool = True
    true_velocities: bool = False
    releases: int = 1  # training releases of 8 s
    train_on_forced: bool = False  # the forced sweep, cut into 1 s pieces, joins the training data
    loss: str = "prop"
    epochs: tuple = (2000,)
    horizons: tuple = (None,)
    quadrature: str = "simpson"
    span: int = 1
    lam: float = 1e-3
    extra: tuple = ()  # further TrainSettings fields as (name, value)
    hparams: tuple = ()
    baseline: str = "traj"  # the L_traj row it is compared with, seed by seed (same data)


VARIANTS = {
    v.name: v
    for v in [
        Variant("base", "L_prop (L_Iτ stage), the docs' measured-log recipe"),
        Variant("traj", "L_traj baseline", loss="traj", epochs=(10, 8), horizons=(2, 0.1)),
        Variant("no_friction", "plant without dry friction or cable", rotor="none"),
        Variant("exact_angles", "angles not quantised", quantize=False),
        Variant("true_velocities", "the simulator's velocities", true_velocities=True),
        Variant(
            "ideal_sensor",
            "exact angles and velocities, no friction",
            rotor="none",
            quantize=False,
            true_velocities=True,
        ),
        Variant("data_64s", "8 releases (64 s)", releases=8),
        Variant("trapezoid", "trapezoid rule", quadrature="trapezoid"),
        Variant("span_50", "L_Iτ over 0.2 s (span 50 Simpson intervals)", span=50),
        Variant("budget_8000", "8000 epochs", epochs=(8000,)),
        Variant("joint_normaliser", "L_Iτ normalised per joint", extra=(("normalize", "joint_momentum"),)),
        Variant(
            "prop_traj_stages",
            "L_Iτ stage, then L_traj stages at the baseline's budget (λ 1)",
            epochs=(2000, 10, 8),
            horizons=(None, 2, 0.1),
            lam=1.0,
        ),
        Variant(
            "span_50_joint", "L_Iτ over 0.2 s, normalised per joint", span=50, extra=(("normalize", "joint_momentum"),)
        ),
        Variant(
            "span_50_traj_stages",
            "L_Iτ over 0.2 s, then L_traj stages at the baseline's budget (λ 1)",
            span=50,
            epochs=(2000, 10, 8),
            horizons=(None, 2, 0.1),
            lam=1.0,
        ),
        Variant(
            "with_forced",
            "the forced sweep in the training data too",
            train_on_forced=True,
            baseline="traj_with_forced",
        ),
        Variant(
            "span_50_with_forced",
            "L_Iτ over 0.2 s, the forced sweep in the training data too",
            span=50,
            train_on_forced=True,
            baseline="traj_with_forced",
        ),
        Variant(
            "traj_with_forced",
            "L_traj baseline, the forced sweep in the training data too",
            loss="traj",
            epochs=(10, 8),
            horizons=(2, 0.1),
            train_on_forced=True,
            baseline="traj_with_forced",
        ),
        Variant(
            "cal_base",
            "calibrated rig: L_Iτ stage (the closed-loop recipe)",
            rig="calibrated",
            baseline="cal_traj_defaults",
        ),
        Variant(
            "cal_prop_defaults",
            "calibrated rig: L_prop, `train`'s defaults",
            rig="calibrated",
            epochs=(100, 20),
            horizons=(2, 1.0),
            lam=1.0,
            quadrature="trapezoid",
            baseline="cal_traj_defaults",
        ),
        Variant(
            "cal_traj_defaults",
            "calibrated rig: L_traj, `train`'s defaults",
            rig="calibrated",
            loss="traj",
            epochs=(100, 20),
            horizons=(2, 1.0),
            quadrature="trapezoid",
            baseline="cal_traj_defaults",
        ),
        Variant(
            "prop_defaults",
            "L_prop, `train`'s defaults",
            epochs=(100, 20),
            horizons=(2, 1.0),
            lam=1.0,
            quadrature="trapezoid",
            baseline="traj_defaults",
        ),
        Variant(
            "traj_defaults",
            "L_traj, `train`'s defaults",
            loss="traj",
            epochs=(100, 20),
            horizons=(2, 1.0),
            quadrature="trapezoid",
            baseline="traj_defaults",
        ),
    ]
}


def _calibrated(name: str, label: str, **changes) -> Variant:
    """A row on the calibrated rig, `train`'s defaults unless ``changes`` say otherwise."""
    defaults = dict(epochs=(100, 20), horizons=(2, 1.0), lam=1.0, quadrature="trapezoid")
    base = dict(rig="calibrated", baseline="cal_traj_defaults", **defaults)
    return Variant(name, "calibrated rig: " + label, **{**base, **changes})


#: the same questions on the rig fitted on the real runs (rotor heavier and far less damped)
CALIBRATED_VARIANTS = [
    _calibrated("cal_prop_no_friction", "L_prop defaults, no dry friction or cable", rotor="none"),
    _calibrated(
        "cal_prop_ideal",
        "L_prop defaults, ideal sensor, no friction",
        rotor="none",
        quantize=False,
        true_velocities=True,
    ),
    _calibrated("cal_prop_spring", "L_prop defaults, learned rotor spring", hparams=(("springs", ("alpha",)),)),
    _calibrated(
        "cal_prop_with_forced",
        "L_prop defaults, the forced sweep in the training data too",
        train_on_forced=True,
        baseline="cal_traj_with_forced",
    ),
    _calibrated(
        "cal_traj_with_forced",
        "L_traj defaults, the forced sweep in the training data too",
        loss="traj",
        train_on_forced=True,
        baseline="cal_traj_with_forced",
    ),
    _calibrated("cal_prop_lambda_10", "L_prop defaults, λ = 10", lam=10.0),
]
VARIANTS.update({v.name: v for v in CALIBRATED_VARIANTS})
VARIANTS["prop_lambda_10"] = dataclasses.replace(
    VARIANTS["prop_defaults"], name="prop_lambda_10", label="L_prop, `train`'s defaults with λ = 10", lam=10.0
)


def rotor_effects(kind: str, seed: int) -> list[Effect]:
    """The rotor of a real rig (issue 64's ranges), drawn from ``seed``; ``"none"``: no rotor effect."""
    if kind == "none":
        return []
    rng = np.random.default_rng([seed, 65])
    sliding = rng.uniform(1e-4, 3e-4)
    return [
        Effect("coulomb_friction", "alpha", sliding),
        Effect("stiction", "alpha", 9.0 * sliding, stribeck_velocity=0.02),  # breakaway 10x sliding
        Effect("hysteretic_spring", "alpha", rng.uniform(1.5e-3, 2.5e-3), play=rng.uniform(0.1, 0.8)),
    ]


def rig_parameters(rig: str) -> dict | None:
    """The rigid-body parameters of ``rig``: None for the datasheet's, or ``"calibrated"``: those
    the diagnosis fitted on the fifteen shipped real runs (results/calibrated_protocol), whose rotor
    is heavier and far less damped, and whose pendulum hardly damped at all."""
    if rig == "nominal":
        return None
    return json.loads(CALIBRATED.read_text())["parameters_after"]


def rig_model(rig: str):
    """The rig's rigid-body model without the rotor's effects (the reference for frequency and
    coupling, and the "nominal" row): the analytic Furuta, or its lumped form in the fitted values."""
    params = rig_parameters(rig)
    if params is None:
        return Furuta()
    layout = layout_for("furuta")
    theta = [params[n] for n in layout.base] + [0.0] * len(layout.candidates)
    return LumpedModel(theta=jnp.asarray(theta, dtype=float), system="furuta")


def release(effects, x0, seconds: float, u=None, parameters=None) -> tuple[np.ndarray, np.ndarray]:
    """States at 500 Hz from ``x0`` under ``u`` (0 V by default) on the MuJoCo plant."""
    if parameters is None:
        plant = MujocoBackend("furuta", SUBSTEPS, effects, timestep=DT / SUBSTEPS)
    else:  # lumped parameters come as a whole plant
        rig = Plant(effects=effects, lumped=parameters, system="furuta", source="calibrated rig")
        plant = MujocoBackend("furuta", SUBSTEPS, timestep=DT / SUBSTEPS, plant=rig)
    plant.reset(np.asarray(x0, float))
    n = int(round(seconds / DT)) + 1
    u = np.zeros(n) if u is None else np.asarray(u, float)
    xs = [np.asarray(x0, float)] + [np.asarray(plant.step(np.array([u[k]]))) for k in range(n - 1)]
    return np.stack(xs), u


def logged(xs, u, v: Variant, name: str) -> Trajectory:
    """What a user logs: angles (quantised unless ``v.quantize`` is off), u; velocities only when
    ``v.true_velocities`` (else estimated later, zero-phase, on the whole log)."""
    t = np.arange(len(u)) * DT
    q = quantize_encoder(xs[:, :2]) if v.quantize else xs[:, :2].copy()
    qd = xs[:, 2:].copy() if v.true_velocities else None
    return Trajectory(t=t, q=q, u=u[:, None], qd=qd, name=name)


def prepared(tr: Trajectory, split: float | None) -> list[Trajectory]:
    """As ``furuta-gym train`` prepares a log (zero-phase velocities unless logged, 1 s pieces)."""
    if tr.qd is not None:
        pieces = [tr] if split is None else _split(tr, split)
        return pieces
    return prepare_log(tr, tr.name, split=split)


def _split(tr: Trajectory, seconds: float) -> list[Trajectory]:
    n = int(round(seconds / tr.dt))
    return [
        Trajectory(
            t=tr.t[k : k + n + 1] - tr.t[k],
            q=tr.q[k : k + n + 1],
            u=tr.u[k : k + n + 1],
            qd=tr.qd[k : k + n + 1],
            name=f"{tr.name}/{k}",
        )
        for k in range(0, len(tr.t) - n, n)
    ]


def dataset(v: Variant, seed: int):
    """(training pieces, test pieces, forced trajectories, plant effects) of ``v`` on ``seed``."""
    effects, params = rotor_effects(v.rotor, seed), rig_parameters(v.rig)
    rng = np.random.default_rng([seed, 7])
    train_logs = []
    for k in range(v.releases):
        x0 = [rng.uniform(-0.1, 0.1), np.pi + rng.choice([-1, 1]) * rng.uniform(0.05, 0.2), 0.0, 0.0]
        train_logs.append(logged(*release(effects, x0, 8.0, parameters=params), v, f"release{k}"))
    test = logged(
        *release(effects, [0.0, np.pi / 2 + rng.uniform(-0.1, 0.1), 0.0, 0.0], 6.0, parameters=params), v, "test"
    )
    t = np.arange(int(round(10.0 / DT)) + 1) * DT
    sweep = 0.75 * np.sin(2 * np.pi * (0.5 * t + 0.175 * t**2))  # 0.5 -> 4 Hz over 10 s
    forced = logged(*release(effects, np.zeros(4), 10.0, sweep, parameters=params), v, "forced")
    pieces = [p for tr in train_logs for p in prepared(tr, 1.0)]
    if v.train_on_forced:
        pieces += prepared(forced, 1.0)
    return pieces, prepared(test, None), prepared(forced, None), effects


def free_frequency(model) -> float:
    """Small-oscillation frequency about hanging, the rotor free, undamped (Hz): issue 65's
    √(∂²V/∂β² · (M⁻¹)₂₂)/2π, the largest root of det(K − ω²M) = 0 at q = 0."""
    return model_frequencies(model, (0.0, 0.0), 1, damped=False)[0]


def score(model, test, plant_frequency: float) -> dict:
    shape = check_potential_shape(model, "furuta")
    errors = window_errors(model, test, WINDOW)
    m0 = np.asarray(model.mass_matrix(jnp.zeros(2)))
    f = free_frequency(model)
    return {
        "free_frequency_hz": f,
        "frequency_error": f / plant_frequency - 1.0,
        "curvature": {e["name"]: e["curvature"] for e in shape["equilibria"]},
        "upright_maximum": bool(shape["physical"]),
        "angle_rmse_rad": float(np.sqrt((errors["rmse"]["alpha"] ** 2 + errors["rmse"]["beta"] ** 2) / 2)),
        "rmse": errors["rmse"],
        "n_diverged": errors.get("n_diverged"),
        "coupling_ratio_at_hanging": float(m0[0, 1] / m0[0, 0]),
    }


def cpu_name() -> str:
    """The CPU's model name (a trained result depends on it: docs/reproduce.md)."""
    for line in Path("/proc/cpuinfo").read_text().splitlines() if Path("/proc/cpuinfo").exists() else []:
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def run(v: Variant, seed: int, out: Path) -> dict:
    pieces, test, forced, effects = dataset(v, seed)
    config = TrainSettings.for_system(
        "furuta",
        epochs=v.epochs,
        horizons=v.horizons,
        quadrature=v.quadrature,
        integral_span=v.span,
        lambda_traj=v.lam,
        seed=seed,
        progress=False,
        checkpoint_every=10**9,
        **dict(v.extra),
    )
    start = time.time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, history = train("dln", "furuta", v.loss, pieces, config, hparams=dict(v.hparams) or None)
    seconds = time.time() - start
    try:  # free prediction does not depend on the scale; the fit is recorded, not needed
        scale = fit_scale(model, forced, rule=v.quadrature if v.quadrature != "hermite" else "simpson", span=v.span)[
            1
        ].factor
    except ValueError as exc:
        scale = str(exc)
    rigid = rig_model(v.rig)
    plant_f = free_frequency(rigid)  # the effects add no stiffness at hanging about a rest
    doc = {
        "variant": v.name,
        "label": v.label,
        "seed": seed,
        "effects": [dataclasses.asdict(e) for e in effects],
        "config": {k: (list(val) if isinstance(val, tuple) else val) for k, val in config.to_json().items()},
        "train_seconds": seconds,
        "scale_fit": scale,
        "plant_free_frequency_hz": plant_f,
        "rig": v.rig,
        "nominal": score(rigid, test, plant_f),
        "model": score(model, test, plant_f),
        "machine": cpu_name(),
        "command": "python studies/free_releases.py " + " ".join(sys.argv[1:]),
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{v.name}_s{seed}.json").write_text(json.dumps(doc, indent=1, default=float) + "\n")
    return doc


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--variants", default=",".join(VARIANTS))
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--out", default=str(OUT))
    args = p.parse_args(argv)
    for name in args.variants.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            m = run(VARIANTS[name], seed, Path(args.out))["model"]
            print(
                f"{name:16s} seed {seed}: f {m['free_frequency_hz']:.2f} Hz ({m['frequency_error']:+.0%}), "
                f"angle RMSE {1e3 * m['angle_rmse_rad']:.0f} mrad, coupling {m['coupling_ratio_at_hanging']:.2f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
