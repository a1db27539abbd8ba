"""The MJCF of a :class:`Plant`: what MuJoCo expresses natively in its elements, the whole plant
as JSON in a ``<custom>`` text that furuta-gym reads back (:meth:`Plant.load`)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from ._backends import MujocoBackend, mjcf_text
from ._plant import PLANT_TEXT
from ._settings import Plant

__all__ = ["plant_mjcf", "save_mjcf"]


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
    (joint stiffness and rest, damping, actuator gain, bias and lag) in their elements, and the
    whole plant (the effects MJCF cannot express included) as JSON in
    ``<custom><text name="furuta_gym_plant">``. Plain MuJoCo loads it with the native terms only;
    furuta-gym's ``plant=`` restores the rest. Numbers are written to full precision (MuJoCo's
    own writer keeps six digits)."""
    if plant.system is None or plant.lumped is None:
        raise ValueError(
            "plant_mjcf: the plant must be a whole one, with its system and lumped parameters "
            "(Plant.nominal(system), or a diagnosis' plant)"
        )
    model = MujocoBackend(plant.system, plant=plant).model
    root = ET.fromstring(mjcf_text(plant.system, actuator_lag=model.na > 0))
    _write_model_into_xml(model, root)
    custom = root.find("custom")
    if custom is None:
        custom = ET.SubElement(root, "custom")
    ET.SubElement(custom, "text", name=PLANT_TEXT, data=json.dumps(plant.to_json(), sort_keys=True))
    ET.indent(root)
    text = ET.tostring(root, encoding="unicode") + "\n"
    mujoco.MjModel.from_xml_string(text)  # it must compile
    return text


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
