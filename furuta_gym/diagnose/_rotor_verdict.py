"""Method step 11's verdict (issue 64): each law's evidence against the model as diagnosed, and
which law the data support, by the trace's rule and the rests."""

from __future__ import annotations

import dataclasses

import numpy as np

from ._drift import REST_LAWS, RestDrift
from ._library import Candidate
from ._rotor_neutral import square_sums
from ._trace import Evidence

#: the two laws: a moving rest and a fixed cable held by a large breakaway (rest_drift's words)
LAWS = (REST_LAWS[0], REST_LAWS[1])


@dataclasses.dataclass
class LawFit:
    """One law fitted on a joint: θ (the library's memoryless part), the cable with memory
    (stiffness, second parameter; (0, 0): none), its predictions of the validation windows and the
    evidence against the model as diagnosed."""

    law: str
    theta: np.ndarray
    cable: tuple
    effects: list[Candidate]
    predictions: np.ndarray
    evidence: Evidence
    physical: bool
    incumbent: bool = False  # the model as diagnosed (the search found this law), not a refit
    #: validation windows whose prediction of the joint the law moves by more than a count (RMS):
    #: those that can carry its evidence (None: the model as diagnosed)
    changed: int | None = None


@dataclasses.dataclass
class RotorLaw:
    """What a joint's rests and the two laws' fits say (``verdict``: one of :data:`LAWS`,
    ``"cannot be told apart"`` or ``"neither"``), and which fit, if any, the diagnosis kept."""

    joint: str
    verdict: str
    reason: str
    rests: RestDrift
    fits: dict[str, LawFit]
    kept: str | None
    head_to_head: Evidence | None = None

    def to_json(self, layout) -> dict:
        def fit(f: LawFit) -> dict:
            coefs = {c.key: float(f.theta[layout.index(c.key)]) for c in f.effects}
            return dict(
                coefficients=coefs,
                cable_stiffness=f.cable[0] if f.cable[0] else None,
                play=f.cable[1] if f.cable[0] else None,
                validation_gain=float(f.evidence.improvement),
                z_score=float(f.evidence.z),
                windows_changed=f.changed,
                windows_scored=int(f.predictions.shape[0]),
                physical=bool(f.physical),
            )

        return dict(
            joint=self.joint,
            verdict=self.verdict,
            reason=self.reason,
            kept=self.kept,
            rests=self.rests.to_json(),
            fits={law: fit(f) for law, f in self.fits.items()},
            head_to_head_z=None if self.head_to_head is None else float(self.head_to_head.z),
        )


def _evidence(pred_before: np.ndarray, pred_after: np.ndarray, measured: np.ndarray) -> Evidence:
    """How much better ``pred_after`` predicts the windows; a window counts by how much the
    predictions differ there (as a stiction's evidence does): a joint at rest in both says nothing."""
    before, after = square_sums(pred_before, measured), square_sums(pred_after, measured)
    if not np.all(np.isfinite(after)):
        return Evidence(-np.inf, -np.inf, int(after.size))
    change = np.sum((pred_after - pred_before) ** 2, axis=(1, 2))
    return Evidence.of_sums(before, after, np.where(np.isfinite(change), change, 0.0))


@dataclasses.dataclass(frozen=True)
class Rule:
    """The trace's thresholds (gain, t), the veto's t, and whether the rests count (a log without
    input: under feedback a controller holds the joint wherever it rests)."""

    min_improvement: float
    z_threshold: float
    veto_t: float
    rests_count: bool


def verdict(fits: dict[str, LawFit], rests: RestDrift, measured, rule: Rule):
    """(verdict, reason, the law kept or None, head-to-head evidence of the moving rest against
    the breakaway): the law that passes the trace's rule and predicts significantly better than
    the other, or that alone passes while the other neither predicts significantly better than
    it (t ≥ the rule's between them: a law whose few windows give it a smaller t may still beat
    the one that passes) nor, gaining the size test, predicts better at all (:func:`_rivals`; not
    asked of the model as diagnosed, ``incumbent``, which only a significantly better law replaces);
    else the one the rests name, if it passes, or, passing the size test alone, does not predict
    significantly worse (as a stiction from rests is added); else, where the rests name neither
    (or do not count), with both laws passing that size test, the one that predicts significantly
    better than the other; else "cannot be told apart" (the better predictor kept) or "neither"."""
    ok = {law: f for law, f in fits.items() if f.physical}
    # the model as diagnosed passed the trace's steps (its stiction by the trace's rule or, under
    # input, on its rests' evidence): it passes here too
    passing = [law for law, f in ok.items() if f.incumbent or f.evidence.passes(rule.min_improvement, rule.z_threshold)]
    said = ", ".join(
        f"{law}{' (the model as diagnosed)' if f.incumbent else ''}: validation gain {f.evidence.improvement:.1%}, "
        f"t {f.evidence.z:.1f}"
        for law, f in fits.items()
    )
    named = rests.verdict if rule.rests_count and rests.verdict in LAWS else None
    rest_words = f"rests: {rests.verdict} ({rests.reason})" + ("" if rule.rests_count else ", not counted under input")
    h2h = _evidence(fits[LAWS[1]].predictions, fits[LAWS[0]].predictions, measured)
    better = LAWS[0] if h2h.z > 0 else LAWS[1]
    if len(passing) == 2 and abs(h2h.z) >= rule.z_threshold:
        return (
            better,
            f"both predict better, the {better} law significantly (t {abs(h2h.z):.1f}; {said}); {rest_words}",
            better,
            h2h,
        )
    beaten = len(passing) == 1 and abs(h2h.z) >= rule.z_threshold and better != passing[0]
    # the model as diagnosed passed the trace's steps: only a law predicting significantly better replaces it
    rivalled = len(passing) == 1 and not beaten and not ok[passing[0]].incumbent and _rivals(ok, passing[0], h2h, rule)
    if len(passing) == 1 and named in (None, passing[0]) and not (beaten or rivalled):
        return passing[0], f"only the {passing[0]} law predicts better ({said}); {rest_words}", passing[0], h2h
    if named is not None and _holds(ok.get(named), rule):
        why = (
            "prediction cannot tell the laws apart"
            if len(passing) == 2
            else "named by the rests, though the other law predicts significantly better"
            if beaten
            else "named by the rests, its prediction agrees"
        )
        return named, f"{why} (t {h2h.z:.1f} between them; {said}); the {rest_words}", named, h2h
    # rests that cannot tell (every large excursion to one side, or too few) or do not count
    # (under input): where both laws gain (a cable is there), the head-to-head takes the rests'
    # part, and the law predicting significantly better than the other is kept on the size test
    # of a stiction from rests (a release, or a sweep's stop, moves the rotor for a second or
    # two: few windows carry either law's gain)
    both = all(_holds(ok.get(law), rule) for law in LAWS)
    if named is None and both and abs(h2h.z) >= rule.z_threshold:
        return (
            better,
            f"both laws predict better, the {better} law significantly better than the other "
            f"(t {abs(h2h.z):.1f}; {said}); the {rest_words}",
            better,
            h2h,
        )
    if len(passing) == 2 or (len(passing) == 1 and (named or beaten or rivalled)):
        better = LAWS[0] if h2h.improvement > 0 else LAWS[1]
        return "cannot be told apart", f"t {h2h.z:.1f} between them ({said}); {rest_words}", better, h2h
    return (
        "neither",
        f"neither law predicts the validation windows better ({said}); {rest_words}{_short_of_t(ok, rule)}",
        None,
        None,
    )


def _short_of_t(ok: dict[str, LawFit], rule: Rule) -> str:
    """Where a law gains the size test short of the trace's t: on how many windows its gain can
    sit (only those the law changes carry its evidence, and a sweep stops the rotor rarely), and
    what would give it more."""
    weak = [f for f in ok.values() if _holds(f, rule) and f.changed is not None]
    return "".join(
        f"; the {f.law} law's gain sits on the {f.changed} of {f.predictions.shape[0]} validation windows "
        f"whose prediction it moves by more than a count, its t short of {rule.z_threshold:g}: a longer log "
        "with more stops and starts (or releases at 0 V) would give it more"
        for f in weak
    )


def _rivals(ok: dict[str, LawFit], passing: str, h2h: Evidence, rule: Rule) -> bool:
    """Whether the law other than ``passing`` gains the size test and predicts the validation
    windows better (sum of squares; ``h2h``: the moving rest against the breakaway), though not
    significantly: naming the one that passes would claim what the windows do not show (its gain
    may sit on many windows, the other's larger gain on a few)."""
    other = next(law for law in LAWS if law != passing)
    return _holds(ok.get(other), rule) and (h2h.improvement > 0) == (other == LAWS[0])


def _holds(fit: LawFit | None, rule: Rule) -> bool:
    """Whether a physical ``fit`` gains the trace's share without predicting significantly worse
    (the size test of a stiction from rests)."""
    return fit is not None and fit.evidence.improvement >= rule.min_improvement and fit.evidence.z > -rule.veto_t
