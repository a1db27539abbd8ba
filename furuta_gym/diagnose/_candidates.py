"""Prepared data → candidates: the library narrowed to what was asked, the candidates these data
cannot test set aside (in the declared model's span, or without excitation), and the trace's
search over the rest (:mod:`._trace`), its steps' evidence recorded."""

from __future__ import annotations

import numpy as np

from ..models import system_definition
from . import _trace as _trace_mod
from ._fitter import _Fitter
from ._problem import free_columns
from ._result import EffectEvidence


def _in_span(prob, layout, free, candidate, fixed_idx) -> str | None:
    """Why a candidate cannot be tested (a combination of the model's own regressors), or None."""
    if candidate.kind.input_dynamics:
        return None
    j = layout.index(candidate.key)
    if candidate.kind.scales_input and layout.learned is None:
        gain_idx = layout.index(system_definition(layout.system).lumped.gain)
        if gain_idx not in fixed_idx:
            return "absorbed: the motor/input gain is a fitted parameter of the declared model"
        if len(fixed_idx) < 2:
            return "not identifiable: the input gain is the only scale anchor (fix a second known parameter to test it)"
    X = prob.R[:, :, free].reshape(prob.R.shape[0] * prob.R.shape[1], int(free.sum()))
    c = prob.R[:, :, j].reshape(-1)
    if np.linalg.norm(c) == 0:
        return "not identifiable: its regressor is zero on these data"
    if X.shape[1] == 0:  # a given model kept as it is: nothing of its own to absorb the effect
        return None
    norms = np.linalg.norm(X, axis=0)
    norms[norms == 0] = 1
    coef, *_ = np.linalg.lstsq(X / norms, c, rcond=None)
    rel = np.linalg.norm(c - (X / norms) @ coef) / np.linalg.norm(c)
    if rel < 1e-6:
        return "absorbed: a combination of the declared model's own regressors"
    return None


def _untestable(fx: _Fitter, library, forced) -> dict[str, EffectEvidence]:
    """Evidence entries for candidates that cannot be tested on these data, by key."""
    out = {}
    # the declared model's own regressors, including parameters held because the data cannot
    # pin them down: an effect in their span is the declared model's, never a discovery
    free_base = free_columns(fx.layout, [], fx.declared_fixed_idx)
    for c in library:
        why = _in_span(fx.fit_prob, fx.layout, free_base, c, fx.declared_fixed_idx)
        if c.joint == "u" and not forced:
            why = "not identifiable: no input excitation"
        if why:
            status = "absorbed" if why.startswith("absorbed") else "not identifiable"
            out[c.key] = EffectEvidence(c.name, c.joint, None, c.unit(fx.spec), False, None, None, status, why)
    return out


def _select(library, candidates):
    if candidates is None:
        return library
    keys = {c.key for c in library}
    bad = [k for k in candidates if k not in keys]
    if bad:
        raise ValueError(f"candidates: unknown {bad}; expected keys from {sorted(keys)}")
    return [c for c in library if c.key in set(candidates)]


def _trace(fx: _Fitter, testable, evidence):
    """Run the search; record the accepted steps' evidence (each member given its partner)."""
    s = fx.settings
    comparer = fx.comparer()
    same = _trace_mod.equivalent_pairs(
        fx.fit_prob, fx.layout, free_columns(fx.layout, [], fx.fixed_idx), fx.weights, testable
    )
    steps, _ = _trace_mod.search(
        comparer,
        testable,
        s.search,
        same,
    )
    for step in steps:
        for other, member in step.equivalents.items():
            c = next(x for x in testable if x.key == other)
            evidence[other] = EffectEvidence(
                c.name,
                c.joint,
                None,
                c.unit(fx.spec),
                False,
                None,
                None,
                "equivalent",
                f"indistinguishable from {member} on these data",
            )
        for c in step.members:
            ev = step.evidence[c.key]
            partner = [o.key for o in step.members if o != c]
            note = (
                f"significant only together with {partner[0]} (pair: held-out gain "
                f"{step.pair_evidence.improvement:.1%}, z {step.pair_evidence.z:.1f}); evidence given it"
                if partner
                else ""
            )
            evidence[c.key] = EffectEvidence(
                c.name, c.joint, None, c.unit(fx.spec), True, ev.improvement, ev.z, "selected", note
            )
    return steps
