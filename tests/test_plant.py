"""A diagnosed plant as a simulator: lumped parameters and effects in MuJoCo (exact against the
lumped Lagrangian model), the MJCF written for other tools and read back, and a diagnosis's
plant end to end (object, JSON, ``diagnose --mjcf``)."""

import dataclasses
import json

import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import furuta_gym.lagrangian as lag
from furuta_gym.cli import main
from furuta_gym.data import save_trajectories
from furuta_gym.diagnose import diagnose
from furuta_gym.diagnose._library import layout_for
from furuta_gym.effects import Effect, can_join, merge_spring_rests
from furuta_gym.envs import MujocoBackend, Plant, plant_mjcf, save_mjcf
from furuta_gym.models import analytic_model
from furuta_gym.rigs import measured_like

FURUTA_EFFECTS = (
    Effect("spring", "alpha", 2e-3, reference=0.1),
    Effect("coulomb_friction", "alpha", 5e-4),
    Effect("viscous_friction", "beta", 1e-5),
    Effect("com_offset", "beta", 0.01),
    Effect("input_gain", "u", -0.1),
    Effect("actuator_lag", "u", 3e-3),
)
NATIVE = (
    Effect("spring", "alpha", 2e-3, reference=0.1),
    Effect("viscous_friction", "beta", 1e-5),
    Effect("input_gain", "u", -0.1),
    Effect("actuator_lag", "u", 3e-3),
)


def _rollout(backend, x0, n=400):
    backend.reset(x0)
    u = np.sin(np.linspace(0.0, 8.0, n))
    return np.array([backend.step([2.0 * ui]) for ui in u])


def _off_nominal(system):
    """Lumped values away from the pinned model's, still a rigid body on an arm."""
    nominal = Plant.nominal(system).lumped
    factors = {
        "J1": 1.3,
        "J1b": 0.8,
        "Jc": 1.1,
        "J2": 0.9,
        "G": 1.2,
        "c_alpha": 2.0,
        "c_beta": 0.5,
        "K": 0.9,
        "m": 1.5,
        "k1": 0.7,
        "k2": 2.0,
        "b1": 1.4,
        "b2": 0.5,
        "gain": 1.1,
    }
    return {k: v * factors[k] for k, v in nominal.items()}


@pytest.mark.parametrize(
    "system,effects",
    [
        ("furuta", FURUTA_EFFECTS[:4] + FURUTA_EFFECTS[5:]),
        ("nmsd", (Effect("spring", "p", 2.0), Effect("input_gain", "u", -0.1))),
    ],
)
def test_nominal_plant_is_the_default_plant(system, effects):
    """(Not with the Furuta's input gain: the lumped form holds the back-EMF in the rotor's damping,
    where the gain does not scale it, as in the lumped model the diagnosis fits.)"""
    x0 = np.array([0.1, 0.5, 0.0, 0.0]) if system == "furuta" else np.array([0.2, 0.0])
    with_plant = _rollout(MujocoBackend(system, plant=Plant.nominal(system, effects)), x0)
    default = _rollout(MujocoBackend(system, effects=effects), x0)
    assert np.max(np.abs(with_plant - default)) < 1e-12 * max(1.0, np.max(np.abs(default)))


@pytest.mark.parametrize("system", ["furuta", "nmsd"])
def test_lumped_plant_is_the_lumped_model(system):
    """Off-nominal lumped values in MuJoCo give the lumped Lagrangian model's M, forces and input
    to round-off: every lumped parameter lands in MuJoCo, none is lost to the MJCF's fixed ratios."""
    lumped = _off_nominal(system)
    backend = MujocoBackend(system, plant=Plant(lumped=lumped, system=system))
    layout = layout_for(system)
    model = layout.model(jnp.asarray([lumped[b] for b in layout.base] + [0.0] * len(layout.candidates)))
    rng = np.random.default_rng(0)
    n = backend.model.nv
    for _ in range(20):
        q, qd, u = rng.uniform(-3, 3, n), rng.uniform(-5, 5, n), rng.uniform(-5, 5, 1)
        d = backend.data
        d.qpos[:], d.qvel[:], d.ctrl[:] = q, qd, u
        with backend.passive_forces():
            mujoco.mj_forward(backend.model, d)
        M = np.zeros((n, n))
        mujoco.mj_fullM(backend.model, d, M)
        jq, jqd = jnp.asarray(q), jnp.asarray(qd)
        np.testing.assert_allclose(M, np.asarray(model.mass_matrix(jq)), rtol=1e-9, atol=1e-15)
        rhs_ref = (
            lag.potential_derived_force(model, jq, jqd)
            - lag.coriolis_force(model, jq, jqd)
            + model.nonconservative_force(jq, jqd)
            + model.input_force(jq, jqd, jnp.asarray(u))
        )
        rhs = d.qfrc_passive + d.qfrc_actuator - d.qfrc_bias
        np.testing.assert_allclose(rhs, np.asarray(rhs_ref), rtol=1e-9, atol=1e-12 * np.max(np.abs(rhs)))


def test_plant_checks_its_parameters():
    lumped = dict(Plant.nominal("furuta").lumped)
    with pytest.raises(ValueError, match=r"missing \['K'\], unknown \['gain'\]"):
        Plant(lumped={**{k: v for k, v in lumped.items() if k != "K"}, "gain": 1.0}, system="furuta")
    with pytest.raises(ValueError, match="joint 'p' is not a joint of furuta"):
        Plant(effects=(Effect("spring", "p", 1.0),), lumped=lumped, system="furuta")
    with pytest.raises(ValueError, match="J2 - J1b = .* must be > 0"):  # a pendulum lighter than a point mass
        MujocoBackend("furuta", plant=Plant(lumped={**lumped, "J2": 0.5 * lumped["J1b"]}, system="furuta"))
    with pytest.raises(ValueError, match="give it alone"):
        MujocoBackend("furuta", effects=NATIVE, plant=Plant(lumped=lumped, system="furuta"))


def test_mjcf_round_trips(tmp_path):
    """The written MJCF: plain MuJoCo steps the native terms exactly as the plant; furuta-gym reads
    the whole plant back, the callback's effects included; nothing is overwritten."""
    x0 = np.array([0.1, 0.5, 0.0, 0.0])
    native = Plant(effects=NATIVE, lumped=_off_nominal("furuta"), system="furuta", source="test")
    path = save_mjcf(native, tmp_path / "rig.xml")
    plain = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(plain)
    data.qpos[:], data.qvel[:] = x0[:2], x0[2:]
    steps = []
    for ui in np.sin(np.linspace(0.0, 8.0, 400)):
        data.ctrl[:] = 2.0 * ui
        mujoco.mj_step(plain, data)
        steps.append(np.concatenate([data.qpos, data.qvel]))
    reference = _rollout(MujocoBackend("furuta", plant=native), x0)
    assert np.max(np.abs(np.array(steps) - reference)) < 1e-10

    full = Plant(effects=FURUTA_EFFECTS, lumped=_off_nominal("furuta"), system="furuta", source="test")
    save_mjcf(full, tmp_path / "full.xml")
    loaded = Plant.load(tmp_path / "full.xml")
    assert loaded == full
    np.testing.assert_array_equal(
        _rollout(MujocoBackend("furuta", plant=loaded), x0), _rollout(MujocoBackend("furuta", plant=full), x0)
    )
    before = path.read_text()
    with pytest.raises(FileExistsError, match="rig.xml exists"):
        save_mjcf(full, path)
    assert path.read_text() == before
    (tmp_path / "plain.xml").write_text(plant_mjcf(native).replace("furuta_gym_plant", "other"))
    with pytest.raises(ValueError, match="not an MJCF written by furuta-gym"):
        Plant.load(tmp_path / "plain.xml")


_DIAGNOSED: dict = {}
#: the plant tests' log: 4 × 5 s with a cable spring (and, for the prediction-first finish, a
#: pendulum Coulomb friction the library is not asked to test); every diagnosis of the file
#: shares one compiled fit
SPRING = Effect("spring", "alpha", 5e-3)
PENDULUM_FRICTION = Effect("coulomb_friction", "beta", 2e-4)
CANDIDATES = ["spring:alpha", "coulomb_friction:alpha"]


def _log(effects=(SPRING,)):
    return measured_like("furuta", list(effects), seed=3, n_trajectories=4, duration=5.0, quantize=False)


def _diagnosed(effects=(SPRING,), finish=None):
    """The diagnosis of :func:`_log` (cached across this file's tests)."""
    key = (tuple(effects), finish)
    if key not in _DIAGNOSED:
        _DIAGNOSED[key] = diagnose(_log(effects), "furuta", candidates=CANDIDATES, finish=finish)
    return _DIAGNOSED[key]


def test_a_diagnosis_gives_its_plant(tmp_path):
    """A diagnosed cable spring ends up in the plant, the JSON carries it, ``--mjcf`` writes it."""
    log = _log()
    res = _diagnosed()
    plant = res.plant()
    springs = [e for e in plant.effects if e.name == "spring"]
    assert len(springs) == 1 and springs[0].coefficient == pytest.approx(5e-3, rel=0.2)
    assert plant.lumped == res.parameters_after and "spring:alpha" in plant.source
    # a plant for prediction: an effect reported inconsistent joins at its tested coefficient
    tested = next(e for e in res.effects if (e.name, e.joint) == ("coulomb_friction", "alpha"))
    assert not tested.significant and res.inconsistent == []
    assert res.plant(include_inconsistent=True) == plant  # nothing inconsistent: the same plant
    marked = dataclasses.replace(tested, coefficient=3e-4, status="inconsistent")
    res_marked = dataclasses.replace(res, effects=[marked if e is tested else e for e in res.effects])
    assert res_marked.plant() == plant
    predictive = res_marked.plant(include_inconsistent=True)
    assert [(e.name, e.coefficient) for e in predictive.effects if e.name == "coulomb_friction"] == [
        ("coulomb_friction", 3e-4)
    ]
    assert "inconsistent, included: coulomb_friction:alpha" in predictive.source
    # one of the wrong physical sign is no plant's effect: left out
    negative = dataclasses.replace(marked, coefficient=-3e-4)
    res_negative = dataclasses.replace(res, effects=[negative if e is tested else e for e in res.effects])
    assert res_negative.plant(include_inconsistent=True) == plant
    (tmp_path / "res.json").write_text(json.dumps(res.to_json()))
    assert Plant.load(tmp_path / "res.json") == plant
    # the plant predicts the log it came from about as the diagnosed model does
    tr = log[0]
    backend = MujocoBackend("furuta", plant=plant)
    backend.reset(np.concatenate([tr.q[0], np.gradient(tr.q[:5], tr.t[:5], axis=0)[0]]))
    sim = np.array([backend.step(u)[:2] for u in tr.u[:250]])
    assert np.sqrt(np.mean((sim[:, 0] - tr.q[1:251, 0]) ** 2)) < 0.05


def test_cli_writes_the_mjcf(tmp_path, capsys):
    """In process, on the log and candidates of the test above (its compiled fit is reused)."""
    save_trajectories(tmp_path / "log.csv", _log(), "furuta")
    out = tmp_path / "rig.xml"
    args = ["diagnose", str(tmp_path / "log.csv"), "--system", "furuta"]
    args += ["--candidates", "spring:alpha,coulomb_friction:alpha", "--mjcf", str(out)]
    assert main(args) == 0
    assert [e.name for e in Plant.load(out).effects] == ["spring"]
    capsys.readouterr()
    assert main(args) != 0 and "refusing to overwrite" in capsys.readouterr().err
    # the flag that shapes the plant needs the plant
    assert main(args[:-2] + ["--with-inconsistent"]) != 0
    err = capsys.readouterr().err
    assert "--with-inconsistent: shapes the --mjcf plant; give --mjcf OUT.xml too" in err
    # the prediction-first plant refits the inconsistent effects: not both
    assert main(args + ["--with-inconsistent", "--prediction-first", "--overwrite"]) != 0
    assert "--prediction-first: its plant refits the inconsistent effects" in capsys.readouterr().err
    # its decision and held-out numbers are shown; here the refit is kept (the tests below) and
    # the written plant is the refit's, both joints' Coulomb friction in it
    assert main(args + ["--prediction-first", "--overwrite"]) == 0
    shown = capsys.readouterr().out
    assert "prediction-first finish: kept" in shown and "position RMSE: diagnosed" in shown
    written = Plant.load(out).effects
    assert [(e.name, e.joint) for e in written] == [
        ("spring", "alpha"),
        ("coulomb_friction", "alpha"),
        ("coulomb_friction", "beta"),
    ]


def test_prediction_first_refit_predicts_better_where_the_diagnosis_claims_nothing():
    """A pendulum Coulomb friction (2e-4 N m) that the diagnosis does not claim — as on the real
    runs, where its test fits it at about 0; here it is not among the candidates — is what the
    prediction-first refit adds: refitted by output error near the planted value, it predicts the
    held-out windows far better than the diagnosed plant with its inconsistent effects, so it is
    kept, and the JSON and ``plant(prediction_first=True)`` carry it."""
    res = _diagnosed((SPRING, PENDULUM_FRICTION), "prediction")
    assert [f"{e.name}:{e.joint}" for e in res.found] == ["spring:alpha"]
    finish = res.prediction
    assert finish.kept, finish.summary()
    assert finish.added == ("coulomb_friction:beta",)
    refit = {(e.name, e.joint): e.coefficient for e in finish.plant.effects}
    assert refit[("coulomb_friction", "beta")] == pytest.approx(2e-4, rel=0.1)
    assert refit[("spring", "alpha")] == pytest.approx(5e-3, rel=0.05)
    # the held-out windows are error_after's, scored the same way
    assert finish.heldout_rmse["diagnosed"] == pytest.approx(res.error_after.trajectory_rmse, rel=1e-9)
    assert finish.heldout_rmse["refit"] < 0.2 * finish.heldout_rmse["with_inconsistent"]
    assert finish.improvement > 0.9 and finish.z_score >= 3.0
    assert res.plant(prediction_first=True) == finish.plant == finish.refit != res.plant()
    doc = json.loads(json.dumps(res.to_json()))["prediction_finish"]
    assert doc["kept"] is True and doc["added"] == ["coulomb_friction:beta"]
    assert Plant.from_json(doc["plant"]) == finish.plant
    assert doc["heldout_trajectory_rmse"]["refit"] == pytest.approx(finish.heldout_rmse["refit"])


def test_prediction_first_on_the_true_form_refits_closer_and_leaves_the_report():
    """On the spring-only log the diagnosed model is already the truth's form: the refit (every
    joint's Coulomb friction added, both fitted at about 0) on windows that start at every point
    of a window-long cycle moves the parameters closer to the truth and predicts the held-out
    windows about 4x better, so it is kept. The report is the one without the finish."""
    plain, res = _diagnosed(), _diagnosed(finish="prediction")
    doc, plain_doc = res.to_json(), plain.to_json()
    assert plain_doc.pop("prediction_finish") is None
    finish_doc = doc.pop("prediction_finish")
    assert json.dumps(doc, default=str) == json.dumps(plain_doc, default=str)
    assert res.table() == plain.table() and res.found == plain.found
    finish = res.prediction
    assert finish.kept and finish.plant == finish.refit != plain.plant()
    assert finish.improvement > 0.9 and finish.z_score >= 3.0 and finish.left_out == ()
    refit = {(e.name, e.joint): e.coefficient for e in finish.plant.effects}
    assert refit[("spring", "alpha")] == pytest.approx(5e-3, rel=1e-3)
    assert abs(refit[("coulomb_friction", "alpha")]) < 1e-5 and abs(refit[("coulomb_friction", "beta")]) < 1e-5
    assert finish.heldout_rmse["diagnosed"] == pytest.approx(plain.error_after.trajectory_rmse, rel=1e-9)
    assert finish_doc["kept"] is True and finish_doc["refit_plant"] == finish.refit.to_json()


def test_prediction_first_keeps_the_plain_plant_when_the_refit_falls_short_of_the_rule():
    """The same log with the diagnosis' rule for a gain asking 99 %: the refit's gain (about 94 %)
    falls short, so the plain plant is returned with the reason and the numbers; the report is
    the one without the finish under the same rule."""
    plain = diagnose(_log(), "furuta", candidates=CANDIDATES, min_improvement=0.99)
    res = diagnose(_log(), "furuta", candidates=CANDIDATES, min_improvement=0.99, finish="prediction")
    doc, plain_doc = res.to_json(), plain.to_json()
    finish_doc = doc.pop("prediction_finish")
    assert plain_doc.pop("prediction_finish") is None
    assert json.dumps(doc, default=str) == json.dumps(plain_doc, default=str)
    finish = res.prediction
    assert not finish.kept and finish.plant == res.plant() == plain.plant()
    assert 0.9 < finish.improvement < 0.99 and "the diagnosis' rule for a gain asks ≥ 99%" in finish.reason
    assert finish_doc["kept"] is False and finish_doc["reason"] == finish.reason
    assert finish.refit is not None and finish_doc["refit_plant"] == finish.refit.to_json()


def test_prediction_first_refuses_what_it_cannot_finish():
    """One error per bad combination, before any fit."""
    log = _log()
    with pytest.raises(ValueError, match="finish: expected one of"):
        diagnose(log, "furuta", finish="best")
    with pytest.raises(ValueError, match="oe=False turns off"):
        diagnose(log, "furuta", finish="prediction", oe=False)
    with pytest.raises(ValueError, match="a diagnosis of a given model has none"):
        diagnose(log, "furuta", finish="prediction", model=analytic_model("furuta"))
    with pytest.raises(ValueError, match="run diagnose\\(..., finish='prediction'\\) first"):
        _diagnosed().plant(prediction_first=True)
    with pytest.raises(ValueError, match="are alternatives"):
        _diagnosed().plant(prediction_first=True, include_inconsistent=True)


def test_a_spring_and_a_constant_torque_on_one_joint_are_one_spring_with_its_rest():
    """How a plant is written from fitted effects (``found``, and ``plant(include_inconsistent=
    True)`` when the spring is the inconsistent one and the constant torque was found)."""
    torque, friction = Effect("constant_torque", "alpha", -1.3e-4), Effect("coulomb_friction", "alpha", 4.4e-4)
    assert merge_spring_rests([torque, friction]) == [torque, friction]
    merged = merge_spring_rests([torque, friction, Effect("spring", "alpha", 8.7e-4)])
    assert [e.name for e in merged] == ["coulomb_friction", "spring"]
    assert merged[1].reference == pytest.approx(-1.3e-4 / 8.7e-4)
    # a torque on another joint, or a spring that pushes away, is left as it is
    other = [Effect("constant_torque", "beta", 1e-4), Effect("spring", "alpha", 8.7e-4)]
    assert merge_spring_rests(other) == other
    assert merge_spring_rests([torque, Effect("spring", "alpha", -1e-4)])[0] == torque


def test_an_effect_joins_a_plant_only_of_its_physical_sign_and_a_breakaway_only_above_its_friction():
    """The one rule for which effects a plant may carry beyond the found ones (the library's
    ``plant(include_inconsistent=True)`` and the head-to-head script's row alike)."""
    coulomb = Effect("coulomb_friction", "beta", 8e-5)
    assert can_join(Effect("spring", "alpha", 8.7e-4), [])
    assert not can_join(Effect("spring", "alpha", -8.7e-4), [])
    assert not can_join(Effect("coulomb_friction", "beta", -1e-5), [])
    assert can_join(Effect("constant_torque", "alpha", -1.3e-4), [])  # either sign is physical
    stiction = Effect("stiction", "beta", 1e-4)
    assert can_join(stiction, [coulomb])
    assert not can_join(stiction, []) and not can_join(stiction, [Effect("coulomb_friction", "alpha", 4e-4)])


def test_the_lumped_model_backend_steps_as_the_plant():
    """The same plant under a model backend (its lumped Lagrangian model plus its effects) follows
    MuJoCo's as the analytic model follows the shipped MJCF (both RK4 at 2 ms)."""
    from furuta_gym.envs import ModelBackend
    from furuta_gym.models import LumpedSystem

    effects = (Effect("spring", "alpha", 2e-3, reference=0.1), Effect("viscous_friction", "beta", 1e-5))
    plant = Plant(effects=effects, lumped=_off_nominal("furuta"), system="furuta")
    x0 = np.array([0.1, 0.5, 0.0, 0.0])
    model = ModelBackend(LumpedSystem.of("furuta", plant.lumped), 0.002, effects=effects, kernel="xla")
    mj = _rollout(MujocoBackend("furuta", plant=plant), x0)
    assert np.max(np.abs(_rollout(model, x0) - mj)) < 1e-8


def test_the_env_takes_a_plant_a_diagnosis_or_a_file(tmp_path):
    """``gym.make(..., plant=...)`` with a Plant, anything with a ``plant()`` (a diagnosis) or a
    file gives the same env; MuJoCo and the lumped model agree on it; it says where it came from."""
    import gymnasium as gym

    plant = Plant(
        effects=(Effect("spring", "alpha", 2e-3),),
        lumped=_off_nominal("furuta"),
        system="furuta",
        source="diagnosis (spring:alpha)",
    )
    (tmp_path / "p.json").write_text(json.dumps({"plant": plant.to_json()}))

    class _Diagnosis:
        def plant(self):
            return plant

    runs = {}
    for name, given, dynamics in (
        ("object", plant, "mujoco"),
        ("diagnosis", _Diagnosis(), "mujoco"),
        ("file", str(tmp_path / "p.json"), "mujoco"),
        ("analytic", plant, "analytic"),
    ):
        env = gym.make("furuta_gym/Furuta-v0", plant=given, dynamics=dynamics)
        assert env.unwrapped.plant.source == "diagnosis (spring:alpha)"
        env.reset(seed=1)
        runs[name] = np.array([env.step(np.array([2.0 * np.sin(0.02 * k)]))[0] for k in range(300)])
        env.close()
    np.testing.assert_array_equal(runs["object"], runs["diagnosis"])
    np.testing.assert_array_equal(runs["object"], runs["file"])
    assert np.max(np.abs(runs["analytic"] - runs["object"])) < 1e-8
    nominal = gym.make("furuta_gym/Furuta-v0")
    nominal.reset(seed=1)
    assert np.max(np.abs(nominal.step(np.array([2.0]))[0] - runs["object"][0])) > 0  # the plant is not the pinned one
    with pytest.raises(ValueError, match="a furuta plant .* for a nmsd env"):
        gym.make("furuta_gym/NMSD-v0", plant=plant)
    with pytest.raises(ValueError, match="runs on dynamics='mujoco' or 'analytic'"):
        gym.make("furuta_gym/Furuta-v0", plant=plant, dynamics=analytic_model("furuta"))


def test_the_shipped_real_data_plant():
    """The README's diagnosis of the 15 QUBE runs: fitted free, J1b lands above J2 (balancing near
    upright hides sin²β), which no rigid pendulum has (J2 − J1b is the pendulum's Ixx − Iyy + Izz
    ≥ 0). The diagnosis holds J1b at its datasheet value, which the held-out data allow, so the
    plant runs in MuJoCo, and its lumped model follows it."""
    from pathlib import Path

    import gymnasium as gym

    path = Path(__file__).resolve().parents[1] / "docs" / "diagnose_qube.json"
    doc = json.loads(path.read_text())
    plant = Plant.load(path)
    assert plant.source.startswith("diagnosis (") and plant.lumped["J1b"] < plant.lumped["J2"]
    assert any(n.startswith("J1b: held at its declared value") for n in doc["notes"])
    assert doc["plant"] == plant.to_json()
    envs = [
        gym.make("furuta_gym/Furuta-v0", plant=plant),
        gym.make("furuta_gym/Furuta-v0", plant=str(path), dynamics="analytic"),
    ]
    states = []
    for env in envs:
        obs, _ = env.reset(seed=0, options={"state": np.array([0.0, 0.3, 0.0, 0.0])})
        for _ in range(100):
            obs, *_ = env.step(np.array([1.0]))
        states.append(obs)
    assert np.all(np.isfinite(states[0])) and np.max(np.abs(states[0] - states[1])) < 1e-6


def test_prediction_first_refit_holds_an_inconsistent_input_delay_at_its_tested_value():
    """The refit's θ has no column for an input delay: an inconsistent one (seen on real runs 1–10)
    is not among the effects it frees, where it used to stop the finish with a ValueError; when the
    diagnosis found no input dynamics, the refit's windows are built on that delay and its plant
    holds it. An inconsistent spring is freed as before."""
    from types import SimpleNamespace

    from furuta_gym.diagnose import layout_for
    from furuta_gym.diagnose._finish import _extra_candidates, _refit_dynamics
    from furuta_gym.diagnose._fit import NO_INPUT_DYNAMICS, InputDynamics
    from furuta_gym.diagnose._result import EffectEvidence

    def evidence(name, joint, coefficient, status):
        return EffectEvidence(name, joint, coefficient, "", status == "selected", 0.2, 2.0, status)

    found = [evidence("coulomb_friction", "alpha", 5e-4, "selected")]
    inconsistent = [
        evidence("input_delay", "u", 1.3e-3, "inconsistent"),
        evidence("spring", "alpha", 7e-4, "inconsistent"),
    ]
    result = SimpleNamespace(
        significant=found, inconsistent=inconsistent, effects=found + inconsistent, input_dynamics=NO_INPUT_DYNAMICS
    )
    added = {c.key: coefficient for c, coefficient in _extra_candidates(layout_for("furuta"), result)}
    assert added == {"spring:alpha": 7e-4, "coulomb_friction:beta": 0.0}
    dyn, held = _refit_dynamics(result)
    assert dyn == InputDynamics("delay", 1.3e-3) and [c.key for c in held] == ["input_delay:u"]
    lagged = SimpleNamespace(**{**vars(result), "input_dynamics": InputDynamics("lag", 4e-3)})
    assert _refit_dynamics(lagged) == (InputDynamics("lag", 4e-3), [])  # the diagnosis' own come first
