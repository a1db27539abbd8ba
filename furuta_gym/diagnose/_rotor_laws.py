"""Issue 64's two laws of a joint on a cable, fitted by prediction and told apart (Method step 11).

A cable whose rest moves (a law with memory, e.g. ``hysteretic_spring``: the play operator) and
a fixed cable held by a breakaway far above the sliding friction both leave a rotor resting off
its cable's neutral; a fixed spring with modest dry friction does neither, so it predicts worse
although its equation error is strong (the equation error leaves rests out). Where a joint's
memoryless spring is vetoed or inconsistent, or its rests name a law (:func:`rest_drift`), or it
was added while the joint's friction leaves open what held it, each law is fitted by output
error on the output-error windows and judged on the fit-set validation windows against the model
as diagnosed, by the trace's rule (where the search found the breakaway's law, that model is the
law's fit, replaced only by a law predicting significantly better; under input also where it
holds the law with a stiction from rests and the refit does not pass):

* **large breakaway**: the fixed spring (its rest as a constant force), Coulomb friction and a
  stiction fitted free, from the breakaway the rests held (:mod:`._rests`);
* **moving rest**: the law with memory (its stiffness and second parameter, the play, fitted) and
  the joint's Coulomb friction. Its neutral is simulated through each window from the state the
  history implies: the play operator run over the log's measured positions (in recorded order,
  across trajectories: a hand that carried the joint between them dragged it; the log's first
  neutral, which no history shows, fitted within the play of its first sample) gives each
  window's starting neutral, and inside the window the neutral is dragged by the predicted
  motion (:class:`furuta_gym.effects.WithNeutral`, advanced after each step as the MuJoCo plant
  advances it). The declared model's parameters stay as diagnosed (or at their nominal values,
  when those predict the law's start better): the windows where the joint moves are few.

The law that passes and predicts better than the other (t ≥ the trace's threshold), or the one
the rests name when prediction cannot tell them apart, is the one the data support; with neither
distinct, both are reported and the better predictor is kept, "cannot be told apart".
"""

from __future__ import annotations

from ._rotor_bracket import broke_away, held_still, holding_forces
from ._rotor_context import (
    Context,
    cable_column,
    ee_with_cable,
    memory_column,
    memory_law_for,
    residual,
    window_errors,
)
from ._rotor_fits import PLAY_GRID, fit_law, fit_laws, model_as_law
from ._rotor_neutral import carried_starts, neutral_paths, predict
from ._rotor_verdict import LAWS, LawFit, RotorLaw, Rule, _evidence, verdict

__all__ = [
    "LAWS",
    "PLAY_GRID",
    "Context",
    "LawFit",
    "RotorLaw",
    "Rule",
    "_evidence",
    "broke_away",
    "cable_column",
    "carried_starts",
    "ee_with_cable",
    "memory_column",
    "fit_law",
    "fit_laws",
    "held_still",
    "holding_forces",
    "memory_law_for",
    "model_as_law",
    "neutral_paths",
    "predict",
    "residual",
    "verdict",
    "window_errors",
]
