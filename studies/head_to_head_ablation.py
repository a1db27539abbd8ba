"""What separates the prediction-first plant from mujoco.sysid? Ablations on the fit runs only.

Issue 66 item 1. The head to head (``diagnose_head_to_head.py``: fit runs 1–10, score runs
11–15) has mujoco.sysid's MJCF terms at 3.72 mrad and the prediction-first plant at 4.01. The
suspects are the ways the prediction-first finish (``furuta_gym/diagnose/_finish.py``) differs
from sysid's fit; each is changed alone here, and every choice is scored on **held-out windows
of runs 1–10 only** (runs 11–15 are never read):

* **folds**: the diagnosis cuts runs 1–10 into 2 s segments and holds out every third (its
  held-out windows, fold 2); the finish refits on the other two thirds. Here every third is a
  fold in turn: each variant is refitted on two folds and scored on the third, so every window
  of runs 1–10 is scored once by a plant that never saw it (1890 windows), and fold 2 alone is
  the finish's own held-out score. The diagnosis itself (its effects, start values, input
  delay) is the one the finish refits, fitted on folds 0 and 1: folds 0 and 1 are held out
  from the refit, not from the diagnosis; fold 2 is held out from both.
* **data** (the keep rule's split: the refit sees two thirds of the windows, sysid all of
  them): the same refit on one fold only, scored on the next one; how much a refit gains from
  twice the windows bounds what the last third could add.
* **delay**: the input delay refitted with everything else (the finish holds the diagnosis'
  value): after the refit, the delay on a 0.25 ms grid within ±0.5 ms chosen by the training
  windows' error, and the plant refitted at it.
* **friction law**: the Karnopp stick–slip the diagnosis predicts with relaxes a joint's
  velocity to zero within one RK4 substep (0.5 ms); MuJoCo's ``frictionloss`` is a soft
  constraint that relaxes it over ~10 ms (default ``solreffriction`` 0.02 s, damping ratio 1:
  b = 2 / (d·timeconst), d ≈ 0.95). The same Karnopp law with a 10 ms relaxation, and the
  smooth tanh(q̇/ε) law with ε = 0.05 rad/s, each in the refit and its scoring.
* **J1b**: the sin²β inertia is held at the datasheet value (the diagnosis' fit gave values no
  rigid bodies have); freed, and held at the rigid-body boundary it crosses if it does.
* **window placement**: the finish cuts its windows back to back from each 2 s segment's first
  sample, so their starts fall anywhere in the runs' 0.1 s input cycle (the runs' input steps
  every 0.1 s); the head-to-head scores, and mujoco.sysid fits, back-to-back windows from each
  run's first sample, which all start at the same point of that cycle. The refit on windows
  placed on that grid, and on windows starting every 10 ms; every variant is scored on the
  held-out folds under each placement.
* **the fit itself**: run to convergence, and started from the datasheet's values or from
  mujoco.sysid's own fit (mapped onto the lumped parameters, :func:`sysid_start`; it fitted
  every window of runs 1–10, so its rows are not held out), and sysid's values scored as they are.
* **the start velocity**: the refit with each training window's start velocity refitted under
  the plant too (3 Gauss-Newton steps on the window's own positions), a fit freed of the
  velocity estimate's error; scored, like every variant, from the measured start state.
* **the input** (``--input-residual``, :func:`input_residual`): the committed prediction-first
  plant's rotor acceleration error binned by the window's mean input and by the rotor's speed
  (is it a dead band or gain of the input, or the rotor's friction?); and the finish with an
  input dead band u_eff = sign(u)·max(|u| − d, 0) after the delay, d fitted with the rest on a
  grid (:data:`DEAD_BANDS`: the refit at each, the best on its training windows kept).
* **in sample** (``--oe-in-sample``, :func:`oe_in_sample`): whether the finish's output-error fit
  reaches the optimum of its own family, started from sysid's values and on sysid's objective,
  and how much of each window's error its start velocity carries.

The folds, the variants' refits and the friction laws are
``furuta_gym.diagnose.finish_ablation``; here are the variants, the head-to-head's fit runs and
mujoco.sysid's fit mapped onto the lumped parameters. Writes ``results/head_to_head/ablation.json``; ``studies/head_to_head_ablation_table.py`` puts
the table into docs/diagnose.md.

    python studies/head_to_head_ablation.py [--variants a,b] [--out results/head_to_head/ablation.json]
    python studies/head_to_head_ablation.py --in-sample   # the committed plants on runs 1–10 themselves
    python studies/head_to_head_ablation.py --oe-in-sample   # the finish's refit and sysid's values on runs 1–10 (oe_in_sample)
    python studies/head_to_head_ablation.py --input-residual   # the force error by input and rotor speed
"""

from __future__ import annotations

import argparse
import copy
import json
import platform
import re
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

from furuta_gym.datasets import load_qube_closed_loop  # noqa: E402
from furuta_gym.diagnose import InputDynamics  # noqa: E402
from furuta_gym.diagnose.finish_ablation import (  # noqa: E402
    FINISH,
    STARTS_EVERY,
    Variant,
    diagnose_with_context,
    rotor_laws_held_out,
    run_variant,
    summarise,
)
from furuta_gym.systems import get_spec  # noqa: E402

FIT_RUNS = list(range(1, 11))
SKIP, WINDOW, OE_WINDOWS, FOLDS = 0.5, 0.1, 64, 3
SYSID = Path(__file__).resolve().parents[1] / "results" / "head_to_head" / "sysid.json"
#: the input dead bands (V) the dead-band variant refits at: the rotor's acceleration error on
#: runs 1–10 is odd in the input and largest at 0.1–0.3 V, about 0.6 rad/s² there, with the
#: rotor's response about 30 rad/s² per volt: tens of mV (beside a refitted rotor friction)
DEAD_BANDS = (0.0, 0.02, 0.04, 0.05, 0.06, 0.07, 0.08, 0.1, 0.14)


VARIANTS = {
    v.name: v
    for v in (
        # the finish until this ablation: the refit on each segment's own back-to-back windows
        Variant("current", "prediction-first until now (refit on each segment's back-to-back windows)"),
        # the keep rule's split: how much the refit gains from its windows
        Variant("one_fold", "refit on one fold only (half the windows)", one_fold=True),
        Variant("converged", "output error run to convergence (60 evaluations, not 15)", max_nfev=60),
        Variant("nominal_start", "refit started from the datasheet's lumped values", start="nominal"),
        Variant("delay", "input delay refitted with the rest", refit_delay=True),
        Variant("j1b", "J1b freed (held at the rigid-body boundary if crossed)", free_j1b=True),
        Variant("karnopp_5ms", "dry friction relaxed over 5 ms", law=("karnopp", 0.005)),
        Variant("karnopp_10ms", "dry friction relaxed over 10 ms", law=("karnopp", 0.01)),
        Variant("karnopp_20ms", "dry friction relaxed over 20 ms", law=("karnopp", 0.02)),
        Variant("mujoco_friction", "dry friction as MuJoCo's soft friction loss (creeps)", law=("mujoco", 0.0)),
        Variant("tanh", "dry friction tanh(q̇/0.05 rad/s) (smooth)", law=("tanh", 0.05)),
        Variant("j1b_20ms", "J1b freed and dry friction relaxed over 20 ms", free_j1b=True, law=("karnopp", 0.02)),
        # where the windows start: the head-to-head's (and sysid's) grid, or every 10 ms
        Variant("grid", "refit on windows on each run's back-to-back grid (as sysid and the score)", placement="grid"),
        Variant("starts", "refit on windows starting every 10 ms (every phase of the input cycle)", placement="starts"),
        Variant(
            "staggered",
            "the finish's refit before its dead band: windows one after another with a 10 ms gap (every start of a cycle)",
            placement="staggered",
        ),
        Variant(
            "finish",
            "the finish as shipped: that refit, then its input dead band search (20/50/100 mV, a 10 mV grid)",
            placement="staggered",
            finish_dead_band=True,
        ),
        Variant(
            "staggered_delay_j1b",
            "the refit before the dead band, with the input delay refitted and J1b freed",
            placement="staggered",
            refit_delay=True,
            free_j1b=True,
        ),
        Variant(
            "staggered_all",
            "the refit before the dead band, with those and dry friction relaxed over 10 ms",
            placement="staggered",
            refit_delay=True,
            free_j1b=True,
            law=("karnopp", 0.01),
        ),
        Variant(
            "starts_sampled",
            "refit on 1260 of the windows starting every 10 ms (drawn at random)",
            placement="starts",
            max_windows=1260,
        ),
        Variant(
            "starts_sampled_10ms",
            "the same, dry friction relaxed over 10 ms",
            placement="starts",
            max_windows=1260,
            law=("karnopp", 0.01),
        ),
        Variant(
            "starts_sampled_all",
            "the same, with the input delay refitted and J1b freed",
            placement="starts",
            max_windows=1260,
            law=("karnopp", 0.01),
            refit_delay=True,
            free_j1b=True,
        ),
        Variant(
            "staggered_dead_band",
            "the refit before the dead band, with an input dead band fitted with the rest (0–140 mV)",
            placement="staggered",
            dead_bands=DEAD_BANDS,
        ),
        Variant(
            "staggered_dead_band_delay_j1b",
            "the refit before the dead band, with the dead band (40–80 mV), the input delay refitted and J1b freed",
            placement="staggered",
            dead_bands=(0.04, 0.05, 0.06, 0.07, 0.08),
            refit_delay=True,
            free_j1b=True,
        ),
        Variant(
            "staggered_refined_starts",
            "the refit before the dead band, each training window's start velocity refitted with the plant (3 steps)",
            placement="staggered",
            start_iterations=3,
        ),
        # sysid's own values (fitted on every window of runs 1-10, so every fold was seen)
        Variant("sysid_start", "refit started from mujoco.sysid's fit", start="given"),
        Variant(
            "sysid_start_20ms",
            "refit from mujoco.sysid's fit, dry friction relaxed over 20 ms",
            start="given",
            law=("karnopp", 0.02),
        ),
        Variant("sysid_plant", "mujoco.sysid's fit in this predictor, not refitted", start="given", refit=False),
        Variant(
            "sysid_plant_mujoco_friction",
            "mujoco.sysid's fit, not refitted, with MuJoCo's soft friction loss",
            start="given",
            refit=False,
            law=("mujoco", 0.0),
        ),
    )
}


#: the shipped MJCF's pendulum mass (sysid's scale anchor), gravity and motor back-EMF bias
MJCF_MASS, GRAVITY, MJCF_BACK_EMF = 0.024, 9.81, 2.1e-4


def sysid_rigid_body(values: dict) -> dict:
    """mujoco.sysid's fitted MJCF terms as the lumped rigid-body and motor values: its pendulum a
    point mass m at l with armature, its rotor inertia, arm, and damping with the MJCF's fixed
    back-EMF."""
    m, r, l = MJCF_MASS, values["arm_length"], values["pendulum_com"]
    return {
        "J1": values["rotor_inertia"] + m * r**2,
        "J1b": m * l**2,
        "Jc": m * r * l,
        "J2": m * l**2 + values["pendulum_armature"],
        "G": m * GRAVITY * l,
        "K": values["motor_gain"],
        "c_alpha": values["alpha_damping"] + MJCF_BACK_EMF,
        "c_beta": values["beta_damping"],
    }


def sysid_start(fx, start, values: dict | None = None):
    """``start`` with mujoco.sysid's fitted terms as lumped values (:func:`sysid_rigid_body`) and
    effects (friction loss as Coulomb friction, its spring and rest, its lateral centre of mass
    as an angle), and its input delay."""
    values = values or json.loads(SYSID.read_text())["parameters"]
    lumped = {
        **sysid_rigid_body(values),
        "coulomb_friction:alpha": values["alpha_frictionloss"],
        "coulomb_friction:beta": values["beta_frictionloss"],
        "spring:alpha": values["alpha_stiffness"],
        "constant_torque:alpha": values["alpha_stiffness"] * values["alpha_springref"],
        "com_offset:beta": -np.arcsin(values["pendulum_com_lateral"] / values["pendulum_com"]),
    }
    theta = np.array(start, dtype=float)
    for name, value in lumped.items():
        theta[fx.layout.index(name)] = value
    return theta, InputDynamics("delay", values["input_delay"])


def mujoco_predict(hsysid, values: dict, x0, u_ext, dt: float) -> np.ndarray:
    """States (W, L + 1, 4) of the sysid fit's MJCF rolled out by MuJoCo (``head_to_head_sysid``'s
    predictor of its SI values, without ``mujoco.sysid``)."""
    return hsysid.predictor_from_values(values)(x0, u_ext, dt)


def sysid_plant(values: dict):
    """mujoco.sysid's fit as a furuta-gym plant (:func:`sysid_start`'s mapping)."""
    from furuta_gym.effects import Effect
    from furuta_gym.envs import Plant

    l = values["pendulum_com"]
    effects = (
        Effect("coulomb_friction", "alpha", values["alpha_frictionloss"]),
        Effect("coulomb_friction", "beta", values["beta_frictionloss"]),
        Effect("spring", "alpha", values["alpha_stiffness"], values["alpha_springref"]),
        Effect("com_offset", "beta", -float(np.arcsin(values["pendulum_com_lateral"] / l))),
        Effect("input_delay", "u", values["input_delay"]),
    )
    return Plant(effects=effects, lumped=sysid_rigid_body(values), system="furuta", source="mujoco.sysid's fit, mapped")


def windows_with_input_before(runs, stride: float | None = None):
    """``prediction_windows`` of ``runs`` (one every ``stride`` s, default back to back) and each
    window's input with the sample before it first (what the MuJoCo rollout delays from)."""
    from furuta_gym.measured import prediction_windows

    x0, us, xs = prediction_windows(runs, WINDOW, stride)
    n, dt = us.shape[1], runs[0].dt
    step = n if stride is None else max(1, int(round(stride / dt)))
    before = []
    for tr in runs:
        u = np.asarray(tr.u, float).reshape(len(tr), -1)
        before += [u[max(a - 1, 0)] for a in range(0, len(tr) - n, step)]
    return x0, np.concatenate([np.asarray(before)[:, None], us], axis=1), xs


def _in_sample_scores(h2h, hsysid, plants: dict, sysid: dict, runs, stride: float | None) -> dict:
    """Position RMSE of sysid rolled out by MuJoCo and of each furuta-gym plant on ``runs``."""
    x0, u_ext, xs = windows_with_input_before(runs, stride)
    out = {"sysid": h2h.score(mujoco_predict(hsysid, sysid, x0, u_ext, runs[0].dt), xs)["position_rmse"]}
    for name, plant in plants.items():
        x0, us, xs = prediction_windows_of(h2h, plant, runs, stride)
        base = h2h.LumpedSystem.of("furuta", plant.lumped)
        field = h2h.lagrangian_field(base, [e for e in plant.effects if not e.kind.on_input], runs[0].dt)
        out[name] = h2h.score(h2h.predict_field(field, x0, us, runs[0].dt), xs)["position_rmse"]
    return {**out, "n_windows": int(len(x0))}


def prediction_windows_of(h2h, plant, runs, stride: float | None):
    """The windows a plant is scored on: its input delay applied from each run's own samples."""
    from furuta_gym.measured import prediction_windows

    return prediction_windows(h2h.with_input(runs, InputDynamics.of_effects(plant.effects)), WINDOW, stride)


def committed_finish_plant(results: Path, without_dead_band: bool = False):
    """The head-to-head's committed prediction-first plant, or its refit without the dead band
    (the plant the dead band was found in: what the finish was before it tried one)."""
    import diagnose_head_to_head as h2h  # where the head to head reads its rows' plants

    doc = json.loads((results / "diagnosed_prediction.json").read_text())
    without = h2h.without_dead_band(doc) if without_dead_band else None
    return without if without is not None else h2h.row_plant(doc, results)


def in_sample(results: Path) -> dict:
    """The committed sysid (MJCF terms) and prediction-first plants on runs 1–10 themselves, with
    the head-to-head's scoring (back-to-back windows of whole runs, sysid rolled out by MuJoCo),
    and with windows starting every 10 ms (``every_phase``): both were fitted on these runs
    (sysid on every back-to-back window, the finish on two thirds of its segments' windows), so
    this says whether the gap is there already on the data both fitted; no reading of runs 11–15."""
    import diagnose_head_to_head as h2h  # the head-to-head's scoring (its module imports MuJoCo's sysid helpers)
    import head_to_head_sysid as hsysid

    sysid = json.loads((results / "sysid.json").read_text())["parameters"]
    plants = {
        "sysid_in_furuta_gym": sysid_plant(sysid),
        "prediction_first": committed_finish_plant(results),
    }
    fit = h2h.load_runs(FIT_RUNS)
    return {
        **_in_sample_scores(h2h, hsysid, plants, sysid, fit, None),
        "per_run": {
            str(k): _in_sample_scores(h2h, hsysid, plants, sysid, [tr], None)
            for k, tr in zip(FIT_RUNS, fit, strict=True)
        },
        "every_phase": _in_sample_scores(h2h, hsysid, plants, sysid, fit, STARTS_EVERY),
    }


#: Gauss-Newton steps on each window's start velocity in :func:`oe_in_sample`'s decomposition
REFINE_STEPS = 3
#: its windows starting at every point of the cycle: one every 30 ms (15 samples, a third of those
#: starting every 10 ms; 15 and the cycle's 50 samples share 5, so every 10 ms point of the
#: cycle is a start, alike)
PHASE_STRIDE = 0.03


def _run_windows(h2h, runs, dyn, stride: float | None):
    """The head-to-head's windows of ``runs`` (whole runs, velocities on the whole log) as the
    diagnosis' output-error windows, under input dynamics ``dyn`` (``segment``: each window's run)."""
    from furuta_gym.diagnose.finish_ablation import Windows
    from furuta_gym.measured import prediction_windows

    x0, us, xs = prediction_windows(h2h.with_input(runs, dyn), WINDOW, stride)
    n, L = get_spec("furuta").n_dof, us.shape[1]
    step = L if stride is None else max(1, int(round(stride / runs[0].dt)))
    run = np.concatenate([np.full(len(range(0, len(tr) - L, step)), k) for k, tr in enumerate(runs)])
    assert run.size == len(x0), "one run index per window"
    return Windows(x0, us, xs[:, 1:, :n], run, runs[0].dt, L)


def rotor_angle_residual(err: np.ndarray, x0: np.ndarray, dt: float, run: np.ndarray) -> dict:
    """What a force depending on the rotor's angle alone could take from windows' errors ``err``
    (W, L, n) started at ``x0`` on runs ``run`` (W,): each window's error fitted as v·t + a·t²/2
    per joint, its acceleration error a regressed on 1, α, α² of the rotor's start angle (least
    squares, per joint), and the RMSE with that part of a taken away: fitted on every window (in
    sample) and, for each run, fitted on the other runs (leave one run out). A proxy: a plant's
    one torque on the rotor reaches the pendulum only through the coupling, and is refitted with
    the rest."""
    L, n = err.shape[1], err.shape[2]
    t = dt * np.arange(1, L + 1)
    basis = np.stack([t, t**2 / 2], axis=1)
    (_, accel) = np.linalg.lstsq(basis, err.transpose(1, 0, 2).reshape(L, -1), rcond=None)[0].reshape(2, -1, n)
    powers = np.vander(x0[:, 0], 3, increasing=True)

    def without(fit: np.ndarray, scored: np.ndarray) -> np.ndarray:
        coefficients = np.linalg.lstsq(powers[fit], accel[fit], rcond=None)[0]  # (3, n)
        return err[scored] - (powers[scored] @ coefficients)[:, None, :] * (t**2 / 2)[None, :, None]

    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    every = np.ones(len(err), bool)
    runs = np.unique(run)
    left_out = {int(k): without(run != k, run == k) for k in runs}
    return {
        "rmse": rms(err),
        "rmse_without": rms(without(every, every)),
        "rmse_without_run_out": rms(np.concatenate(list(left_out.values()))),
        "per_run": {str(k): [rms(err[run == k]), rms(e)] for k, e in left_out.items()},
        "coefficients": np.linalg.lstsq(powers, accel, rcond=None)[0].T.tolist(),  # per joint: 1, α, α²
        "correlation_alpha_squared": [float(np.corrcoef(x0[:, 0] ** 2, accel[:, j])[0, 1]) for j in range(n)],
    }


#: ridge penalties tried in :func:`force_error_bounds` (the best one is reported: a bound)
RIDGE = (100.0, 300.0, 1000.0, 3000.0, 10000.0, 30000.0)


def force_error_bounds(err: np.ndarray, x0: np.ndarray, us: np.ndarray, dt: float, run: np.ndarray) -> dict:
    """How much any plant could take from windows' errors ``err`` (W, L, n) by a better force:
    each window's error fitted as v·t + a·t²/2 per joint, and the RMSE with a taken away
    (``oracle``: each window's own a, which no plant knows), and with a predicted by a smooth
    function of the window's start state and input (600 random Fourier features of α, β off its
    nearest rest, α̇, β̇, the input at the start, its mean, and the means of the window's two
    halves; ridge, fitted for each run on the other runs) under each of :data:`RIDGE`."""
    L, n = err.shape[1], err.shape[2]
    t = dt * np.arange(1, L + 1)
    basis = np.stack([t, t**2 / 2], axis=1)
    (_, accel) = np.linalg.lstsq(basis, err.transpose(1, 0, 2).reshape(L, -1), rcond=None)[0].reshape(2, -1, n)
    u = us[:, :, 0]
    beta = x0[:, 1] - np.pi * np.round(x0[:, 1] / np.pi)
    F = np.stack(
        [x0[:, 0], beta, x0[:, 2], x0[:, 3], u[:, 0], u.mean(1), u[:, : L // 2].mean(1), u[:, L // 2 :].mean(1)], 1
    )
    F = (F - F.mean(0)) / F.std(0)
    rng = np.random.default_rng(0)
    Z = np.cos(F @ (rng.normal(size=(F.shape[1], 600)) / 1.5) + rng.uniform(0, 2 * np.pi, 600))
    Z = np.concatenate([Z, F, np.ones((len(F), 1))], axis=1)
    taken = lambda a: err - a[:, None, :] * (t**2 / 2)[None, :, None]  # noqa: E731
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    out = {"rmse": rms(err), "oracle": rms(taken(accel)), "ridge": {}}
    for lam in RIDGE:
        predicted = np.zeros_like(accel)
        for k in np.unique(run):
            A = Z[run != k]
            predicted[run == k] = Z[run == k] @ np.linalg.solve(
                A.T @ A + lam * np.eye(Z.shape[1]), A.T @ accel[run != k]
            )
        out["ridge"][f"{lam:g}"] = rms(taken(predicted))
    return out


def oe_in_sample(fx, res) -> dict:
    """Does the finish's output-error fit reach the optimum of its own family? In sample on runs
    1–10, all of whose windows mujoco.sysid fitted: the finish's refit (its start, free set and
    staggered windows of the fit folds) and mujoco.sysid's values (:func:`sysid_start`, its input
    delay) on the finish's objective and on the head-to-head's scoring; the refit started from
    sysid's values; the same refit on sysid's own objective (every back-to-back window of runs
    1–10) from either start. Then where the error comes from: each window's start velocity
    refined by ``REFINE_STEPS`` Gauss-Newton steps on the window's own positions under the plant
    (an oracle: it reads the positions it is scored on; a start velocity also takes up much of an
    error that grows like t², as a force's does), and each plant's RMS error at each step of the
    windows (``profile``: an error of the start velocity grows like t, one of the force like t²);
    the encoder's count alone as a uniform quantisation error; and what a force depending on the
    rotor's angle, or any force, could take from the refit's error (:func:`rotor_angle_residual`,
    :func:`force_error_bounds`). Scored with
    the head-to-head's 4 RK4 substeps; fitted with the diagnosis'."""
    import diagnose_head_to_head as h2h
    from furuta_gym.diagnose import Candidate
    from furuta_gym.diagnose.finish_ablation import (
        predict_windows,
        refit as finish_refit,
        refit_start,
        refit_windows,
        window_square_sums,
    )
    from furuta_gym.signals import ENCODER_COUNTS_PER_REV

    fit = h2h.load_runs(FIT_RUNS)
    start, chosen, dyn = refit_start(fx, res)
    chosen += [c for c in (Candidate("spring", "alpha"),) if c not in chosen]  # sysid fits a spring
    sysid, sysid_dyn = sysid_start(fx, start)

    def rmse(theta, win, refine: int = 0) -> float:
        ss = window_square_sums(fx.layout, theta, win, h2h.SUBSTEPS, refine)
        return float(np.sqrt(ss.sum() / (ss.size * win.q[0].size)))

    def profile(theta, win) -> list[float]:
        """RMS position error of both angles at each step of the windows."""
        err = predict_windows(fx.layout, theta, win, h2h.SUBSTEPS) - win.q
        return [float(x) for x in np.sqrt(np.mean(err**2, axis=(0, 2)))]

    def refit(theta, d, win):
        return finish_refit(fx, theta, chosen, d, win)

    finish_win = {d: refit_windows(fx, fx.fit_segs, d) for d in (dyn, sysid_dyn)}
    ours = refit(start, dyn, finish_win[dyn])
    from_sysid = refit(sysid, sysid_dyn, finish_win[sysid_dyn])
    grid = {d: _run_windows(h2h, fit, d, None) for d in (dyn, sysid_dyn)}
    phases = {d: _run_windows(h2h, fit, d, PHASE_STRIDE) for d in (dyn, sysid_dyn)}
    plants = {"prediction_first": (ours, dyn), "sysid": (sysid, sysid_dyn)}
    lumped = lambda th: {b: float(th[i]) for i, b in enumerate(fx.layout.base)}  # noqa: E731
    ours_err = predict_windows(fx.layout, ours, phases[dyn], h2h.SUBSTEPS) - phases[dyn].q
    return {
        "finish_objective": {k: rmse(th, finish_win[d]) for k, (th, d) in plants.items()},
        "grid": {k: rmse(th, grid[d]) for k, (th, d) in plants.items()},
        "from_sysid": {
            "finish_objective": rmse(from_sysid, finish_win[sysid_dyn]),
            "grid": rmse(from_sysid, grid[sysid_dyn]),
            "lumped": lumped(from_sysid),
        },
        "grid_fit": {
            "from_sysid": rmse(refit(sysid, sysid_dyn, grid[sysid_dyn]), grid[sysid_dyn]),
            "from_finish_start": rmse(refit(start, sysid_dyn, grid[sysid_dyn]), grid[sysid_dyn]),
        },
        "phases": {k: rmse(th, phases[d]) for k, (th, d) in plants.items()},
        "refined_start": {
            "grid": {k: rmse(th, grid[d], REFINE_STEPS) for k, (th, d) in plants.items()},
            "phases": {k: rmse(th, phases[d], REFINE_STEPS) for k, (th, d) in plants.items()},
        },
        "profile": {
            "grid": {k: profile(th, grid[d]) for k, (th, d) in plants.items()},
            "phases": {k: profile(th, phases[d]) for k, (th, d) in plants.items()},
        },
        "rotor_angle_residual": rotor_angle_residual(ours_err, phases[dyn].x0, phases[dyn].dt, phases[dyn].segment),
        "force_error_bounds": force_error_bounds(
            ours_err, phases[dyn].x0, phases[dyn].us, phases[dyn].dt, phases[dyn].segment
        ),
        "quantisation_rmse": 2 * np.pi / ENCODER_COUNTS_PER_REV / np.sqrt(12),
        "free": [c.key for c in chosen],
        "windows": {
            "finish_objective": int(finish_win[dyn].x0.shape[0]),
            "grid": int(grid[dyn].x0.shape[0]),
            "phases": int(phases[dyn].x0.shape[0]),
        },
        "phase_stride": PHASE_STRIDE,
        "refine_steps": REFINE_STEPS,
    }


#: bin edges of :func:`input_residual`: a window's mean input (V) and its rotor's start speed (rad/s)
INPUT_BINS = (-10.0, -3.0, -1.0, -0.3, -0.1, 0.0, 0.1, 0.3, 1.0, 3.0, 10.0)
SPEED_BINS = (-10.0, -1.0, -0.3, -0.1, -0.03, 0.0, 0.03, 0.1, 0.3, 1.0, 10.0)


def _binned(value: np.ndarray, edges, accel: np.ndarray, split: np.ndarray) -> list[dict]:
    """Mean (and its standard error) of ``accel`` in each bin of ``value``, all and split by the
    sign of ``split``."""

    def cell(m):
        y = accel[m]
        return [float(y.mean()), float(y.std() / np.sqrt(y.size)), int(y.size)] if y.size > 5 else None

    return [
        {
            "bin": [lo, hi],
            "all": cell(m := (value >= lo) & (value < hi)),
            "pos": cell(m & (split > 0)),
            "neg": cell(m & (split < 0)),
        }
        for lo, hi in zip(edges[:-1], edges[1:], strict=False)
    ]


def _window_accelerations(h2h, runs, lumped: dict, effects, dyn):
    """Windows of ``runs`` starting every :data:`PHASE_STRIDE` s under a plant (``lumped`` values,
    memoryless ``effects``, input dynamics ``dyn``): each window's start state, its mean input as
    logged and delayed (before any dead band), each joint's acceleration error a (measured −
    predicted, the window's error fitted as v·t + a·t²/2) and the position RMSE."""
    from furuta_gym.measured import prediction_windows

    dt = runs[0].dt
    x0, us, xs = prediction_windows(h2h.with_input(runs, dyn), WINDOW, PHASE_STRIDE)
    field = h2h.lagrangian_field(h2h.LumpedSystem.of("furuta", lumped), effects, dt)
    err = xs[:, 1:, :2] - h2h.predict_field(field, x0, us, dt)[:, 1:, :2]
    L = err.shape[1]
    t = dt * np.arange(1, L + 1)
    basis = np.stack([t, t**2 / 2], axis=1)
    accel = np.linalg.lstsq(basis, err.transpose(1, 0, 2).reshape(L, -1), rcond=None)[0].reshape(2, -1, 2)[1]
    logged = InputDynamics(dyn.kind, dyn.seconds)  # the delay alone
    u = prediction_windows(h2h.with_input(runs, logged), WINDOW, PHASE_STRIDE)[1][:, :, 0].mean(1)
    return x0, u, accel, float(np.sqrt(np.mean(err**2)))


def _regression(a: np.ndarray, columns: list[np.ndarray]) -> dict:
    X = np.stack([np.ones_like(a), *columns], axis=1)
    c = np.linalg.lstsq(X, a, rcond=None)[0]
    return {"coefficients": c.tolist(), "r2": float(1 - (a - X @ c).var() / a.var())}


def _fold_plants(h2h, runs, doc: dict) -> dict:
    """The finish now and the dead-band variant as refitted on folds 0 and 1 (the finish's own
    split), on the same windows: RMSE, and the rotor's acceleration error by the mean input."""
    from furuta_gym.diagnose.finish_ablation import DeadBandInput
    from furuta_gym.effects import Effect

    out = {}
    for name in (FINISH, "staggered_dead_band"):
        if name not in doc["variants"]:
            continue
        f = doc["variants"][name]["per_fold"][2]
        effects = [Effect(*key.split(":"), value) for key, value in f["effects"].items()]
        dyn = DeadBandInput(f["input_dynamics"], f["delay"], f.get("dead_band", 0.0))
        _, u, accel, rmse = _window_accelerations(h2h, runs, f["theta"], effects, dyn)
        out[name] = {
            "rmse": rmse,
            "dead_band": dyn.dead_band,
            "by_input": _binned(u, INPUT_BINS, accel[:, 0], u),
            "on_input": _regression(accel[:, 0], [u, np.sign(u)]),
        }
    return out


def input_residual(results: Path, doc: dict) -> dict:
    """Is the committed prediction-first refit's force error, without its dead band (the plant it was found in), on runs 1–10 a function of the input
    (a dead band, a voltage-dependent gain) or of the rotor's velocity (its friction)? Windows
    starting every 30 ms (:data:`PHASE_STRIDE`), each window's error (measured − predicted)
    fitted as v·t + a·t²/2 per joint; the rotor's a binned by the window's mean input (the input
    the plant sees, delayed) split by the sign of the rotor's start speed, and by that speed
    split by the sign of the input; and a regressed on 1, ū, sgn ū and on 1, α̇, sgn α̇ (R²).
    ``fold_plants``: the same for the refit before the dead band and the dead-band variant refitted on folds 0
    and 1 (:func:`_fold_plants`)."""
    import diagnose_head_to_head as h2h

    plant = committed_finish_plant(results, without_dead_band=True)
    runs = h2h.load_runs(FIT_RUNS)
    effects = [e for e in plant.effects if not e.kind.on_input]
    x0, u, accel, _ = _window_accelerations(h2h, runs, plant.lumped, effects, InputDynamics.of_effects(plant.effects))
    speed, a = x0[:, 2], accel[:, 0]
    return {
        "windows": int(len(x0)),
        "stride": PHASE_STRIDE,
        "rotor_accel_rms": float(np.sqrt(np.mean(a**2))),
        "by_input": _binned(u, INPUT_BINS, a, speed),
        "by_speed": _binned(speed, SPEED_BINS, a, u),
        "pendulum_by_input": _binned(u, INPUT_BINS, accel[:, 1], speed),
        "on_input": _regression(a, [u, np.sign(u)]),
        "on_speed": _regression(a, [speed, np.sign(speed)]),
        "on_both": _regression(a, [u, np.sign(u), speed, np.sign(speed)]),
        "fold_plants": _fold_plants(h2h, runs, doc),
    }


def cable_laws() -> dict:
    """Issue 64's two rotor laws on runs 1–10 (Method step 11 asked on the rotor whatever the data
    say): each law fitted by the diagnosis onto its model as diagnosed, and scored, with that
    model, on the diagnosis' held-out segments (fold 2) (:func:`rotor_laws_held_out`)."""
    data = load_qube_closed_loop(FIT_RUNS, skip_seconds=SKIP)
    doc = rotor_laws_held_out(data, "furuta", window=WINDOW, oe_max_windows=OE_WINDOWS)
    return doc | {
        "machine": f"{platform.node()} {platform.processor() or platform.machine()}",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }


def dump(doc: dict) -> str:
    """The result file's text: per-window sums to 5 significant digits, each list on one line.
    Windows starting every 10 ms are ten times as many: their sums are kept for the finish until
    the ablation and the refit before the dead band (``FINISH``) only, which later variants are compared with
    (each variant's comparisons are kept in its ``by_placement``; the summaries keep their full
    precision). ``doc`` itself keeps every sum."""
    doc = copy.deepcopy(doc)
    for name, r in doc["variants"].items():
        for fold in r["per_fold"]:
            if name not in ("current", FINISH):
                fold.pop("sums_starts", None)
            for key in [k for k in fold if k.startswith("sums")]:
                fold[key] = [float(f"{x:.5g}") for x in fold[key]]
    text = json.dumps(doc, indent=1, default=float)
    number = r"-?(?:[0-9.]+(?:[eE][-+]?[0-9]+)?|Infinity)"
    return (
        re.sub(rf"\[\s*({number}(?:,\s*{number})*)\s*\]", lambda m: "[" + re.sub(r"\s+", "", m.group(1)) + "]", text)
        + "\n"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/head_to_head/ablation.json")
    ap.add_argument("--variants", default=",".join(VARIANTS), help=f"comma list of {list(VARIANTS)}")
    ap.add_argument("--in-sample", action="store_true", help="only the committed plants scored on runs 1–10")
    ap.add_argument(
        "--oe-in-sample",
        action="store_true",
        help="only the finish's refit and sysid's values on runs 1–10's own windows (oe_in_sample)",
    )
    ap.add_argument(
        "--input-residual",
        action="store_true",
        help="only the committed prediction-first refit's rotor acceleration error (without its dead band) by input and speed",
    )
    ap.add_argument(
        "--cable-laws",
        action="store_true",
        help="only issue 64's two rotor laws (Method step 11, asked always) on runs 1–10, scored on fold 2",
    )
    args = ap.parse_args()
    names = args.variants.split(",")
    if unknown := [v for v in names if v not in VARIANTS]:
        ap.error(f"--variants: unknown {unknown}; expected some of {list(VARIANTS)}")
    out = Path(args.out)
    doc = json.loads(out.read_text()) if out.is_file() else {"variants": {}}
    for name, r in doc["variants"].items():  # labels are the code's (a variant's meaning can be renamed)
        if name in VARIANTS:
            r["label"] = VARIANTS[name].label
    if args.cable_laws:
        doc["cable_laws"] = cable_laws()
        print(json.dumps(doc["cable_laws"], indent=1))
        return out.write_text(dump(doc)) and None
    if args.input_residual:
        doc["input_residual"] = input_residual(Path(__file__).resolve().parents[1] / "results" / "head_to_head", doc)
        print(json.dumps(doc["input_residual"], indent=1))
        return out.write_text(dump(doc)) and None
    if args.in_sample:
        doc["in_sample"] = in_sample(Path(__file__).resolve().parents[1] / "results" / "head_to_head")
        print(doc["in_sample"])
        return out.write_text(dump(doc)) and None
    res, fx, wall = diagnose_with_context(
        load_qube_closed_loop(FIT_RUNS, skip_seconds=SKIP), "furuta", window=WINDOW, oe_max_windows=OE_WINDOWS
    )
    print(f"diagnosis and finish: {wall:.0f} s; {res.prediction.reason}", flush=True)
    if args.oe_in_sample:
        doc["oe_in_sample"] = oe_in_sample(fx, res)
        print(doc["oe_in_sample"])
        return out.write_text(dump(doc)) and None
    for name in names:
        doc["variants"][name] = run_variant(fx, res, VARIANTS[name], given=sysid_start)
        doc["variants"] = {k: doc["variants"][k] for k in VARIANTS if k in doc["variants"]}
        summarise(doc, fx.L, get_spec("furuta").n_dof)
        doc.update(
            fit_runs=FIT_RUNS,
            folds=FOLDS,
            window_seconds=WINDOW,
            found=[f"{e.name}:{e.joint}" for e in res.found],
            finish_heldout_rmse=res.prediction.heldout_rmse,
            machine=f"{platform.node()} {platform.processor() or platform.machine()}",
            date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        )
        out.write_text(dump(doc))
        r = doc["variants"][name]
        print(f"{r['label']:60s} held-out {r['heldout_rmse'] * 1e3:.3f} mrad {r.get('vs_current', '')}", flush=True)


if __name__ == "__main__":
    main()
