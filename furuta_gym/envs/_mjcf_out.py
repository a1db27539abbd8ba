"""The MJCF of a :class:`Plant`: what plain MuJoCo can run of it in its elements (native terms,
and MuJoCo's own forms of dry friction, a constant force, a centre-of-mass offset and an input
delay), a comment naming what it could not express, and the whole plant as JSON in a
``<custom>`` text that furuta-gym reads back (:meth:`Plant.load`)."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

from ..effects import Effect, MujocoForm
from ._mujoco_backend import MujocoBackend, mjcf_text
from ._plant import PLANT_TEXT
from ._settings import Plant

__all__ = ["plant_mjcf", "save_mjcf", "plain_forms", "PlainForms"]


def save_mjcf(plant: Plant, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write ``plant`` as an MJCF file (:func:`plant_mjcf`); an existing file is kept unless
    ``overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (--force) to replace it")
    path.write_text(plant_mjcf(plant))
    return path


def plant_mjcf(plant: Plant) -> str:
    """The system's MJCF with the plant's bodies, inertias, gravity and every native term
    (joint stiffness and rest, damping, actuator gain, bias and lag) in their elements, what plain
    MuJoCo has a form of for the rest (:func:`plain_forms`: dry friction as joint friction loss, a
    constant force on the actuated joint as the actuator's bias, a centre-of-mass offset as the
    body's centre of mass turned about its hinge, an input delay as the actuator's delay), a
    comment at the top saying which effects are approximated and which it could not express, and
    the whole plant as JSON in ``<custom><text name="furuta_gym_plant">``. Plain MuJoCo runs it,
    one step per control period as the shipped MJCF; furuta-gym's ``plant=`` restores the plant
    exactly from the JSON. Numbers are written to full precision (MuJoCo's own writer keeps six
    digits)."""
    if plant.system is None or plant.lumped is None:
        raise ValueError(
            "plant_mjcf: the plant must be a whole one, with its system and lumped parameters "
            "(Plant.nominal(system), or a diagnosis' plant)"
        )
    model = MujocoBackend(plant.system, plant=plant).model
    root = ET.fromstring(mjcf_text(plant.system, actuator_lag=model.na > 0))
    _write_model_into_xml(model, root)
    forms = plain_forms(plant.effects, model)
    _write_plain_forms(forms, model, root)
    root.insert(0, ET.Comment(_plain_comment(plant, forms)))
    custom = root.find("custom")
    if custom is None:
        custom = ET.SubElement(root, "custom")
    ET.SubElement(custom, "text", name=PLANT_TEXT, data=json.dumps(plant.to_json(), sort_keys=True))
    ET.indent(root)
    text = ET.tostring(root, encoding="unicode") + "\n"
    mujoco.MjModel.from_xml_string(text)  # it must compile
    return text


@dataclasses.dataclass
class PlainForms:
    """What plain MuJoCo can run of a plant's effects beyond the native terms
    (:meth:`~furuta_gym.effects.EffectKind.to_mujoco`'s stiffness, damping, gain and lag), and
    which effects it cannot: per dof the friction loss, the actuator's constant bias, per hinge
    the angle its body's centre of mass is turned by, the actuator delay (s)."""

    frictionloss: np.ndarray
    bias: float = 0.0
    turn: dict[int, float] = dataclasses.field(default_factory=dict)
    delay: float = 0.0
    #: the effects written in these forms, those of them only approximately, those left out
    written: list[Effect] = dataclasses.field(default_factory=list)
    approximated: list[Effect] = dataclasses.field(default_factory=list)
    missing: list[Effect] = dataclasses.field(default_factory=list)


def _constant(law, limit: float = 1e3) -> float | None:
    """The value of a law of one velocity if it is one constant over ±``limit`` (a Coulomb
    friction's), else None (a breakaway that fades with speed)."""
    values = [float(law(v)) for v in np.linspace(-limit, limit, 9)]
    return values[0] if max(values) - min(values) <= 1e-12 * max(abs(values[0]), 1e-300) else None


def plain_forms(effects, model: mujoco.MjModel) -> PlainForms:
    """Sort ``effects`` (a plant's, written into ``model`` by :class:`MujocoBackend`) by what plain
    MuJoCo can do with those its callback or env would apply: each kind says where it goes
    (:meth:`~furuta_gym.effects.EffectKind.to_mujoco`), and those MuJoCo has a form of are kept."""
    out = PlainForms(np.zeros(model.nv))
    actuated = int(model.jnt_dofadr[model.actuator_trnid[0, 0]]) if model.nu else -1
    for e in effects:
        dof = -1 if e.kind.on_input else int(model.jnt_dofadr[model.joint(e.joint).id])
        form = MujocoForm(np.zeros(model.nv), np.zeros(model.nv), np.zeros(model.nv), shift=np.zeros(model.nv))
        e.kind.to_mujoco(e, dof, form)
        limit = _constant(e.dry_friction_limit(np)) if e.kind.is_dry_friction else None
        if e.kind.input_dynamics == "delay" and hasattr(model, "actuator_delay"):
            out.delay += e.coefficient
            out.approximated.append(e)
        elif e.kind.on_input and (e.kind.shapes_input or (e.kind.has_memory and e.kind.input_dynamics != "lag")):
            out.missing.append(e)  # an input law MuJoCo has no form of (a dead band), or one with memory
            continue
        elif e.kind.on_input or not (form.laws or form.neutrals or form.shift.any()):
            continue  # native: a spring, damping, the gain, the lag
        elif limit is not None:
            out.frictionloss[dof] += limit
        elif e.kind.is_constant_force and dof == actuated:
            out.bias += e.coefficient / float(model.actuator_gear[0, 0])
        elif form.shift.any() and _turnable(model, dof):
            out.turn[dof] = out.turn.get(dof, 0.0) + float(form.shift[dof])
            out.approximated.append(e)
        else:
            out.missing.append(e)
            continue
        out.written.append(e)
    return out


def _turnable(model: mujoco.MjModel, dof: int) -> bool:
    """A hinge whose body carries no other body: turning its centre of mass shifts its gravity
    potential and nothing else of the kinematics."""
    joint = int(model.dof_jntid[dof])
    body = int(model.jnt_bodyid[joint])
    return model.jnt_type[joint] == mujoco.mjtJoint.mjJNT_HINGE and not np.any(model.body_parentid[1:] == body)


def _write_plain_forms(forms: PlainForms, model: mujoco.MjModel, root: ET.Element) -> None:
    """Put :func:`plain_forms` into the MJCF: friction loss on joints (the constraint solver on,
    with MuJoCo's default soft friction), the bias, turned centres of mass, the delay."""
    for j in range(model.njnt):
        dof = int(model.jnt_dofadr[j])
        if forms.frictionloss[dof] > 0:
            _named(root, "joint", model.joint(j).name).set("frictionloss", _numbers(forms.frictionloss[dof]))
    if forms.frictionloss.any():
        option = root.find("option")
        assert option is not None
        flag = option.find("flag")
        (flag if flag is not None else ET.SubElement(option, "flag")).set("constraint", "enable")
    actuator = _named(root, "*", model.actuator(0).name) if model.nu else None
    if actuator is not None and forms.bias:
        bias = model.actuator_biasprm[0, :3].copy()
        bias[0] += forms.bias
        actuator.set("biasprm", _numbers(bias))
    for dof, angle in forms.turn.items():
        _turn_centre_of_mass(model, root, int(model.dof_jntid[dof]), angle)
    if actuator is not None and forms.delay > 0:
        # MuJoCo reads the delayed control from a history of past controls, one per step
        steps = math.ceil(forms.delay / model.opt.timestep)
        actuator.attrib.update(delay=_numbers(forms.delay), nsample=str(steps + 2), interp="zoh")


def _turn_centre_of_mass(model: mujoco.MjModel, root: ET.Element, joint: int, angle: float) -> None:
    """The hinge's body with its centre of mass (and inertia frame) turned by −``angle`` about
    the hinge: gravity's potential becomes V(q − angle), a ``com_offset``'s law."""
    body = int(model.jnt_bodyid[joint])
    axis, anchor = model.jnt_axis[joint], model.jnt_pos[joint]
    turn = np.zeros(4)
    mujoco.mju_axisAngle2Quat(turn, axis, -angle)
    pos, quat = np.zeros(3), np.zeros(4)
    mujoco.mju_rotVecQuat(pos, model.body_ipos[body] - anchor, turn)
    mujoco.mju_mulQuat(quat, turn, model.body_iquat[body])
    inertial = _named(root, "body", model.body(body).name).find("inertial")
    assert inertial is not None  # _write_model_into_xml wrote every body's
    inertial.attrib.update(pos=_numbers(pos + anchor), quat=_numbers(quat))


def _effect_names(effects) -> str:
    return ", ".join(f"{e.name}:{e.joint}" for e in effects)


def _plain_comment(plant: Plant, forms: PlainForms) -> str:
    """What the file says about itself: what plain MuJoCo runs, what only approximately, what not."""
    lines = [
        f" furuta-gym plant of {plant.system}" + (f" ({plant.source})" if plant.source else "") + ".",
        " Plain MuJoCo runs its native terms (bodies, inertias, joint stiffness and rest, damping,",
        " armature, actuator gain, bias and lag), dry friction as joint frictionloss (MuJoCo's soft",
        " friction constraint; the plant holds a joint at rest exactly) and a constant force on the",
        " actuated joint in the actuator's bias. Step it once per control period, as the shipped MJCF.",
    ]
    for e in forms.approximated:
        if e.kind.on_input:
            lines.append(
                f" Approximated: {e.name}:{e.joint} {e.coefficient:.6g} s as the actuator's delay: MuJoCo reads"
                " past controls held per step, so a delay below one step acts as one step."
                " Starting mid-run, fill the history with mj_initCtrlHistory."
            )
        else:
            lines.append(
                f" Approximated: {e.name}:{e.joint} {e.coefficient:.6g} as the body's centre of mass turned"
                " about its hinge: exact in gravity, its inertia terms move by the same small angle."
            )
    missing = _effect_names(forms.missing) or "none"
    lines.append(f" Not expressed in MJCF (furuta-gym's plant= restores them from <custom>): {missing}.")
    return "\n".join(lines) + "\n"


def _numbers(values) -> str:
    return " ".join(repr(float(v)) for v in np.atleast_1d(values))


def _named(root: ET.Element, tag: str, name: str) -> ET.Element:
    found = root.find(f".//{tag}[@name='{name}']")
    if found is None:
        raise ValueError(f"the shipped MJCF has no <{tag} name={name!r}>")
    return found


def _write_model_into_xml(model: mujoco.MjModel, root: ET.Element) -> None:
    """What :func:`apply_parameters` wrote into ``model``'s arrays, into the matching elements of
    the same MJCF: bodies' positions and inertials, joints' native terms, the actuator's gain,
    bias and dynamics, gravity."""
    for i in range(1, model.nbody):
        body = _named(root, "body", model.body(i).name)
        body.set("pos", _numbers(model.body_pos[i]))
        inertial = body.find("inertial")
        if inertial is None:
            inertial = ET.SubElement(body, "inertial")
        inertial.attrib.clear()
        inertial.attrib.update(
            pos=_numbers(model.body_ipos[i]),
            quat=_numbers(model.body_iquat[i]),
            mass=_numbers(model.body_mass[i]),
            diaginertia=_numbers(model.body_inertia[i]),
        )
    for j in range(model.njnt):
        joint, dof = _named(root, "joint", model.joint(j).name), int(model.jnt_dofadr[j])
        joint.attrib.update(
            armature=_numbers(model.dof_armature[dof]),
            damping=_numbers(model.dof_damping[dof]),
            stiffness=_numbers(model.jnt_stiffness[j]),
            springref=_numbers(model.qpos_spring[int(model.jnt_qposadr[j])]),
        )
    for a in range(model.nu):
        actuator = _named(root, "*", model.actuator(a).name)
        actuator.attrib.update(gainprm=_numbers(model.actuator_gainprm[a]), biasprm=_numbers(model.actuator_biasprm[a]))
        if model.na:
            actuator.set("dynprm", _numbers(model.actuator_dynprm[a]))
    option = root.find("option")
    if option is None:
        option = ET.SubElement(root, "option")
    option.set("gravity", _numbers(model.opt.gravity))
