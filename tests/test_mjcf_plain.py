"""The MJCF a plant is written as, run by plain MuJoCo (no furuta-gym callback, env or JSON): it
carries what MuJoCo has a form of (dry friction as friction loss, a constant torque in the
actuator's bias, a centre-of-mass offset as the centre of mass turned about its hinge, the input
delay as MuJoCo's actuator delay) and reproduces the plant's own prediction, and its comment names
what it approximates and what it could not express."""

import math
import subprocess
import sys
from pathlib import Path

import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from furuta_gym.diagnose import InputDynamics
from furuta_gym.effects import Effect, WithEffects
from furuta_gym.envs import Plant, plant_mjcf
from furuta_gym.lagrangian import forward_dynamics_with_dry_friction
from furuta_gym.models import LumpedSystem
from furuta_gym.simulate import rollout_zoh

DT, SUBSTEPS = 0.002, 4
#: the effects a diagnosis of the QUBE finds (docs/diagnose.md), of about their sizes
QUBE_LIKE = (
    Effect("coulomb_friction", "alpha", 4e-4),
    Effect("spring", "alpha", 7e-4, reference=-0.1),
    Effect("constant_torque", "alpha", -1e-4),
    Effect("com_offset", "beta", -0.004),
    Effect("coulomb_friction", "beta", 7e-5),
    Effect("input_delay", "u", 1.6e-3),
)


def _plant_prediction(plant: Plant, x0, us) -> np.ndarray:
    """The plant's own open-loop prediction, as the diagnosis and the head-to-head score it: the
    lumped model with its effects, dry friction that holds a joint at rest, the input delayed
    (period-averaged) and held, RK4 with 4 substeps."""
    base = LumpedSystem.of("furuta", plant.lumped)
    dry = [e for e in plant.effects if e.kind.is_dry_friction]
    model = WithEffects(base, [e for e in plant.effects if not (e.kind.is_dry_friction or e.kind.on_input)])

    def field(x, u):
        q, qd = x[:2], x[2:]
        limit = jnp.zeros(2)
        for e in dry:
            j = e.joint_index(base.spec)
            limit = limit.at[j].add(e.dry_friction_limit()(qd[j]))
        return jnp.concatenate([qd, forward_dynamics_with_dry_friction(model, limit, q, qd, u, DT / SUBSTEPS)])

    delay = sum(e.coefficient for e in plant.effects if e.kind.input_dynamics == "delay")
    u = InputDynamics("delay", delay).apply(us, DT)
    return np.asarray(rollout_zoh(None, jnp.asarray(x0), jnp.asarray(u), DT, SUBSTEPS, field))


def _plain_mujoco(xml: str, x0, us) -> np.ndarray:
    """Plain MuJoCo on the file: one step per control period, as the shipped MJCF."""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = x0[:2], x0[2:]
    states = [np.asarray(x0, float)]
    for u in us:
        data.ctrl[:] = u
        mujoco.mj_step(model, data)
        states.append(np.concatenate([data.qpos, data.qvel]))
    return np.array(states)


def test_plain_mujoco_reproduces_the_plant():
    """1 s from hanging at rest under a ±0.25 V square wave, the rotor stuck by its friction a
    fifth of the time: plain MuJoCo on the written file follows the plant's prediction to 5 mrad
    RMS in both angles (measured 2.8), where the file's native terms alone (the plant without the
    effects MuJoCo runs only through the new forms) are 80 mrad off."""
    t = np.arange(500) * DT
    us = (0.25 * np.sign(np.sin(2 * np.pi * 1.5 * t)) + 0.05 * np.sin(2 * np.pi * 4.1 * t))[:, None]
    x0 = np.zeros(4)
    plant = Plant.nominal("furuta", QUBE_LIKE)
    reference = _plant_prediction(plant, x0, us)
    assert np.mean(np.abs(reference[:, 2]) < 1e-6) > 0.15  # the rotor sticks: friction matters
    plain = _plain_mujoco(plant_mjcf(plant), x0, us)
    rms = math.sqrt(np.mean((plain[:, :2] - reference[:, :2]) ** 2))
    assert rms < 5e-3
    native = Plant.nominal("furuta", [e for e in QUBE_LIKE if e.kind.in_potential])  # the spring alone
    native_rms = math.sqrt(np.mean((_plain_mujoco(plant_mjcf(native), x0, us)[:, :2] - reference[:, :2]) ** 2))
    assert native_rms > 10 * rms


def test_the_file_says_what_it_approximates_and_what_it_cannot_express():
    plant = Plant.nominal(
        "furuta", QUBE_LIKE + (Effect("stiction", "alpha", 2e-4), Effect("quadratic_drag", "beta", 1e-6))
    )
    text = plant_mjcf(plant)
    comment = text[text.index("<!--") : text.index("-->")]
    assert (
        "Not expressed in MJCF (furuta-gym's plant= restores them from <custom>): stiction:alpha, quadratic_drag:beta."
        in comment
    )
    assert "Approximated: com_offset:beta" in comment and "Approximated: input_delay:u" in comment
    model = mujoco.MjModel.from_xml_string(text)
    assert model.dof_frictionloss.tolist() == [4e-4, 7e-5]
    assert not model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    assert model.actuator_delay[0] == 1.6e-3 and model.actuator_history[0, 0] * model.opt.timestep > 1.6e-3
    assert model.actuator_biasprm[0, 0] == -1e-4
    # the pendulum's centre of mass turned by +0.004 rad about its hinge (x): it hangs straight
    # down at β = -0.004, V(β) -> V(β + 0.004), the offset's law
    ipos = model.body_ipos[model.body("pendulum").id]
    assert math.atan2(ipos[1], -ipos[2]) == pytest.approx(0.004, abs=1e-12)
    everything = plant_mjcf(Plant.nominal("furuta", QUBE_LIKE))
    assert "Not expressed in MJCF (furuta-gym's plant= restores them from <custom>): none." in everything
    nominal = mujoco.MjModel.from_xml_string(plant_mjcf(Plant.nominal("furuta")))
    assert nominal.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONSTRAINT and nominal.nhistory == 0


def test_the_docs_table_matches_its_results():
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run(
        [sys.executable, str(root / "studies" / "mjcf_plain_table.py"), "--check"], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
