"""The MJCF that ``diagnose --mjcf`` writes, run by plain MuJoCo on the head-to-head's test runs.

``save_mjcf`` / ``plant_mjcf`` write what plain MuJoCo can run of a plant: its native terms and
MuJoCo's own forms of dry friction (joint friction loss), a constant torque on the actuated joint
(the actuator's bias), a centre-of-mass offset (the centre of mass turned about its hinge) and the
input delay (the actuator's delay). Here the head-to-head's two diagnosed plants (fit on runs
1–10: the diagnosed plant and the prediction-first one, from ``results/head_to_head/``) are
written to MJCF and rolled out by MuJoCo alone — ``mujoco.MjModel.from_xml_string`` and
``mj_step``, no furuta-gym callback, env or JSON — on the head-to-head's windows of runs 11–15
(``studies/diagnose_head_to_head.py``: 0.1 s back-to-back from the measured state, the logged
input held over each 2 ms period, one MuJoCo step per period as the file says), each window's
control history filled with the log's inputs before it (``mj_initCtrlHistory``), and scored by
the head-to-head's own ``score``. Beside each: the plant's own score (furuta-gym's prediction,
recomputed here), the same plant's MJCF with its native terms only (what ``--mjcf`` wrote before
these forms), and the shipped nominal MJCF in plain MuJoCo.

Writes ``results/head_to_head/mjcf_plain.json``; ``studies/mjcf_plain_table.py`` puts the table
into docs/diagnose.md.

    python studies/mjcf_plain_mujoco.py
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import furuta_gym  # noqa: F401  first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import mujoco
import numpy as np

import diagnose_head_to_head as h2h
from furuta_gym.assets import asset_path
from furuta_gym.envs import Plant, plain_forms, plant_mjcf
from furuta_gym.measured import prediction_windows

OUT = Path(__file__).resolve().parents[1] / "results" / "head_to_head" / "mjcf_plain.json"
#: the head-to-head's plants: row name -> (label, where its plant is in the row's result file)
PLANTS = {
    "diagnosed_prediction": ("furuta-gym diagnosed, prediction-first", ("prediction_finish", "plant")),
    "diagnosed": ("furuta-gym diagnosed", ("diagnosis", "plant")),
}


def windows_with_history(trajs, seconds: float, before: int = 16):
    """The head-to-head's windows (x0, held inputs, measured states) and, per window, the log's
    ``before`` inputs preceding it (the first sample repeated before a run's start, as the
    diagnosis' delay pads)."""
    x0, us, xs = prediction_windows(trajs, seconds)
    n, history = us.shape[1], []
    for tr in trajs:  # as prediction_windows cuts them
        u = np.asarray(tr.u, float).reshape(len(tr), -1)
        history += [u[np.maximum(np.arange(a - before, a), 0)] for a in range(0, len(tr) - n, n)]
    return x0, us, xs, np.asarray(history)


def plain_mujoco(xml: str, x0, us, history, dt: float) -> np.ndarray:
    """States (W, L + 1, 4) of the MJCF ``xml`` stepped by MuJoCo alone, ``us`` held over each
    period of ``dt``; a delayed actuator's history holds the inputs before each window."""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    steps = int(round(dt / model.opt.timestep))
    kept = int(model.actuator_history[0, 0]) if model.nhistory else 0
    stamps = (np.arange(-kept, 0) * model.opt.timestep).reshape(-1, 1)
    out = np.empty((len(x0), us.shape[1] + 1, 4))
    for w in range(len(x0)):
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = x0[w, :2], x0[w, 2:]
        if kept:  # one stored control per MuJoCo step, each its period's logged input
            period = np.floor_divide(np.arange(-kept, 0), steps)
            mujoco.mj_initCtrlHistory(model, data, 0, stamps, np.ascontiguousarray(history[w][period, :1]))
        out[w, 0] = x0[w]
        for k in range(us.shape[1]):
            data.ctrl[:] = us[w, k]
            mujoco.mj_step(model, data, steps)
            out[w, k + 1, :2], out[w, k + 1, 2:] = data.qpos, data.qvel
    return out


def native_only(plant: Plant) -> Plant:
    """The plant with only the effects MuJoCo runs in its native terms: what ``--mjcf`` gave
    plain MuJoCo before it wrote MuJoCo's forms of the others."""
    forms = plain_forms(plant.effects, mujoco.MjModel.from_xml_string(plant_mjcf(plant)))
    left = {id(e) for e in forms.written + forms.missing}
    return dataclasses.replace(plant, effects=tuple(e for e in plant.effects if id(e) not in left))


def plant_row(name: str, test, windows) -> dict:
    label, where = PLANTS[name]
    doc = json.loads((OUT.parent / f"{name}.json").read_text())
    plant = Plant.from_json(doc[where[0]][where[1]])
    # what --mjcf writes: the finish's refit without what MJCF cannot express, when it has one
    written = doc[where[0]].get("mujoco_plant")  # only a finish with a dead band has one
    written = plant if written is None else Plant.from_json(written)
    x0, us, xs, history = windows
    dt = test[0].dt
    xml = plant_mjcf(written)
    forms = plain_forms(written.effects, mujoco.MjModel.from_xml_string(xml))
    return {
        "name": name,
        "label": label,
        "effects": [f"{e.name}:{e.joint}" for e in plant.effects],
        "written_effects": [f"{e.name}:{e.joint}" for e in written.effects],
        "written_refitted_without": [f"{e.name}:{e.joint}" for e in plant.effects if e.kind.shapes_input]
        if written is not plant
        else [],
        "approximated": [f"{e.name}:{e.joint}" for e in forms.approximated],
        "not_expressed": [f"{e.name}:{e.joint}" for e in forms.missing],
        "committed_plant_position_rmse": doc["position_rmse"],
        "plant": h2h.score_plant(plant, test),
        "plain_mujoco": h2h.score(plain_mujoco(xml, x0, us, history, dt), xs),
        "native_terms_only": h2h.score(plain_mujoco(plant_mjcf(native_only(written)), x0, us, history, dt), xs),
    }


def main() -> None:
    test = h2h.load_runs(h2h.TEST_RUNS)
    windows = windows_with_history(test, h2h.WINDOW)
    x0, us, xs, history = windows
    nominal = h2h.score(plain_mujoco(asset_path("furuta.xml").read_text(), x0, us, history, test[0].dt), xs)
    rows = [plant_row(name, test, windows) for name in PLANTS]
    doc = {
        "test_runs": h2h.TEST_RUNS,
        "window_seconds": h2h.WINDOW,
        "mujoco": mujoco.__version__,
        "nominal_mjcf": nominal,
        "rows": rows,
        "machine": h2h.machine(),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }
    OUT.write_text(json.dumps(doc, indent=1) + "\n")
    for r in rows:
        print(
            f"{r['label']:45s} plant {1e3 * r['plant']['position_rmse']:.2f} mrad, plain MuJoCo "
            f"{1e3 * r['plain_mujoco']['position_rmse']:.2f}, native terms only "
            f"{1e3 * r['native_terms_only']['position_rmse']:.2f}"
        )
    print(f"nominal MJCF in plain MuJoCo {1e3 * nominal['position_rmse']:.2f} mrad")


if __name__ == "__main__":
    main()
