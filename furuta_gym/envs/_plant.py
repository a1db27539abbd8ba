"""Reading a diagnosed plant (:class:`~furuta_gym.envs.Plant`) from a diagnosis JSON, a plant JSON
or an MJCF file that :func:`~furuta_gym.envs.save_mjcf` wrote."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

import mujoco

from ..effects import Effect

__all__ = ["PLANT_TEXT", "plant_document", "effect_json"]

#: the name of the MJCF ``<custom><text>`` element that holds a plant, as JSON, for furuta-gym
PLANT_TEXT = "furuta_gym_plant"


def plant_document(path: str | os.PathLike) -> dict[str, Any]:
    """The plant JSON in ``path``: a diagnosis JSON's ``"plant"``, a plant JSON, or the
    ``<custom>`` text of an MJCF that :func:`~furuta_gym.envs.save_mjcf` wrote."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"plant file {path} does not exist")
    if path.suffix.lower() == ".xml":
        model = mujoco.MjModel.from_xml_path(str(path))
        text = _custom_text(model, PLANT_TEXT)
        if text is None:
            raise ValueError(
                f"{path}: no <custom><text name={PLANT_TEXT!r}> element: not an MJCF written by "
                "furuta-gym (plain MuJoCo loads it, without the effects MJCF lacks)"
            )
        return json.loads(text)
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not JSON ({err})") from None
    if isinstance(doc, dict) and "plant" in doc:
        doc = doc["plant"]
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: no plant in it (a diagnosis of a learned model has none)")
    return doc


def effect_json(e: Effect) -> dict[str, Any]:
    out = {"name": e.name, "joint": e.joint, "coefficient": float(e.coefficient)}
    defaults = {f.name: f.default for f in dataclasses.fields(Effect) if f.name not in out}
    out.update({k: float(getattr(e, k)) for k, d in defaults.items() if getattr(e, k) != d})
    return out


def _custom_text(model: mujoco.MjModel, name: str) -> str | None:
    """The data of the ``<custom><text>`` called ``name``, or None."""
    for i in range(model.ntext):
        if mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_TEXT, i) == name:
            start, size = int(model.text_adr[i]), int(model.text_size[i])
            return bytes(model.text_data[start : start + size]).rstrip(b"\0").decode()
    return None
