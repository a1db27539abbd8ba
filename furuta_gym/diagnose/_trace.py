"""Tracing the residual to library effects: cross-validated evidence and the search over candidates.

Evidence for adding effects ``added`` to a model with effects ``chosen`` is measured by
cross-validation over the fit segments: both models are fitted (equation error) on the other
folds, and the normalised residual sum of squares of the left-out fold is compared block by block
(``block_seconds`` long, much longer than the residual's correlation time). Two numbers decide:

* the **size**: the relative drop of the total held-out sum, 1 − S₁/S₀ ≥ ``min_improvement``;
* the **consistency**: the t statistic of the per-block log ratios log(S₀,b / S₁,b) ≥
  ``z_threshold``, each block weighted by what it can say about the candidate: the energy of the
  candidate's own (weighted) regressor in the block. A log ratio keeps each block's size of
  improvement (a rank test throws it away) in relative terms; the weight keeps blocks where the
  candidate hardly acts (a rotor resting, or moving a few counts at high frequency) from counting
  for or against it, where they would otherwise bury the blocks that carry the evidence (a spring
  where the rotor wanders, friction where it reverses). The input dynamics weigh every block alike (see :meth:`Comparer._regressor_energy`). The
  variance is the weighted mean's own (a sandwich estimate over blocks), so the t is honest about
  how few blocks carry the weight; it grows as √(informative blocks) with more data: more data
  never weakens a real effect.

The search adds, round after round, the candidate with the strongest evidence (largest t) among
those that pass and have a physical sign, and tests every remaining candidate again against the
enlarged model. When no single candidate passes, pairs among the ``pair_pool`` largest-gain
candidates are tested: a pair passes if the pair as a whole passes and each member still improves
the model that holds the other (t ≥ ``member_z_threshold``) — effects that only help together,
such as a cable spring whose pull only shows once the dry friction that holds the rotor is
modelled. Candidates the data cannot tell apart are grouped (see :func:`equivalent_pairs`).
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import Sequence

import numpy as np
from scipy.special import ndtri_exp
from scipy.stats import t as student_t

from ._library import Candidate
from ._problem import block_sums, fit_equation_error, free_columns, momentum_norm
from ._settings import SearchSettings

__all__ = ["Evidence", "Comparer", "Step", "search", "log_ratio_t"]


@dataclasses.dataclass(frozen=True)
class Evidence:
    """Cross-validated evidence of adding effects: relative drop of the held-out normalised
    residual sum of squares, the t statistic ``z`` of per-block log ratios, and the block count.
    ``sums`` keeps the per-block sums (before, after) and each block's recording, to say where an
    effect helps and where it hurts."""

    improvement: float
    z: float
    n_blocks: int
    sums: tuple | None = dataclasses.field(default=None, compare=False, repr=False)

    def passes(self, min_improvement: float, z_threshold: float) -> bool:
        return self.improvement >= min_improvement and self.z >= z_threshold

    @classmethod
    def of_sums(cls, s0: np.ndarray, s1: np.ndarray, weights=None, recordings=None) -> "Evidence":
        """Evidence of the per-block (or per-window) sums ``s1`` against ``s0``; ``weights``: what
        each block can say about the candidate (None: every block alike)."""
        improvement = float(1.0 - s1.sum() / s0.sum()) if s0.sum() > 0 else 0.0
        return cls(improvement, log_ratio_t(s0, s1, weights), int(s0.size), (s0, s1, recordings))

    def by_recording(self) -> dict[str, float]:
        """{recording: relative drop of its held-out sum}, for the recordings with a nonzero sum."""
        if self.sums is None or self.sums[2] is None:
            return {}
        s0, s1, names = self.sums
        out = {}
        for name in dict.fromkeys(names):
            m = names == name
            if s0[m].sum() > 0:
                out[str(name)] = float(1.0 - s1[m].sum() / s0[m].sum())
        return out


@dataclasses.dataclass
class Step:
    """One accepted step of the search: one effect, or a pair found together."""

    members: tuple[Candidate, ...]
    evidence: dict[str, Evidence]  # per member: its evidence given the model before it (and its partner)
    pair_evidence: Evidence | None = None
    equivalents: dict[str, str] = dataclasses.field(default_factory=dict)  # other key -> member key


def equivalent_pairs(prob, layout, free_base, weights, candidates, threshold: float = 0.99):
    """{key: {keys}} of candidates these data cannot tell apart: their weighted regressor columns,
    with the declared model's own free columns projected out, are correlated beyond ``threshold``
    (a pendulum's centre-of-mass offset and a constant torque when the pendulum stays near one
    angle). The input delay is not a column of θ and is never grouped."""
    cols = [c for c in candidates if not c.kind.input_dynamics]
    W = weights[None, :, None]
    X = (prob.R[:, :, free_base] * W).reshape(prob.R.shape[0] * prob.R.shape[1], int(free_base.sum()))
    Q = np.linalg.qr(X / np.maximum(np.linalg.norm(X, axis=0), 1e-300))[0] if X.shape[1] else X
    out: dict[str, set[str]] = {c.key: set() for c in candidates}
    if not cols:
        return out
    C = np.stack([(prob.R[:, :, layout.index(c.key)] * W[:, :, 0]).reshape(-1) for c in cols], 1)
    C = C - Q @ (Q.T @ C)
    norms = np.linalg.norm(C, axis=0)
    ok = norms > 1e-12 * max(1.0, norms.max())
    U = C / np.where(ok, norms, 1.0)
    corr = np.abs(U.T @ U)
    for i, a in enumerate(cols):
        for k, b in enumerate(cols):
            if i != k and ok[i] and ok[k] and corr[i, k] > threshold:
                out[a.key].add(b.key)
    return out


def log_ratio_t(s0: np.ndarray, s1: np.ndarray, weights=None) -> float:
    """t statistic of the per-block log ratios log(s0/s1), weighted by ``weights`` (None or all
    zero: equal weights): positive when the candidate lowers the held-out residual. Blocks whose
    sums are zero in both models (all joints at rest) are skipped. The standard error is the
    weighted mean's sandwich estimate, √(n/(n−1)·Σw²(r − r̄)²) with Σw = 1, which for equal
    weights is the ordinary one."""
    ok = (s0 > 0) & (s1 > 0)
    r = np.log(s0[ok] / s1[ok])
    if r.size < 3:
        return 0.0
    w = np.ones(r.size) if weights is None else np.asarray(weights, float)[ok]
    w = w / w.sum() if w.sum() > 0 else np.full(r.size, 1.0 / r.size)
    mean = float(w @ r)
    var = float(r.size / (r.size - 1) * (w**2 @ (r - mean) ** 2))
    if var == 0.0:
        return 0.0 if mean == 0.0 else float(np.sign(mean) * np.inf)
    return _as_normal(mean / np.sqrt(var), 1.0 / float(w @ w) - 1.0)


def block_weights(energy: np.ndarray) -> np.ndarray:
    """Per-block evidence weights from (blocks, candidates) regressor energies: each block's
    share of each candidate's own total, summed over a pair's members (so that they count alike).
    A block weighs what it can say about the candidate; where its regressor is idle, nothing."""
    return (energy / np.maximum(energy.sum(axis=0), 1e-300)).sum(axis=1)


def _as_normal(t: float, dof: float) -> float:
    """The standard normal quantile with the tail probability of ``t`` under Student's t with
    ``dof`` degrees of freedom (the weights' effective number of blocks − 1): a t carried by a few
    blocks is weaker evidence than the same t over many. Fewer than 2 effective blocks: 0."""
    if dof < 1.0:
        return 0.0
    return float(np.sign(t) * -ndtri_exp(student_t.logsf(abs(t), dof)))


class Comparer:
    """Cross-validated comparisons on one problem (stacked fit-segment regressors)."""

    def __init__(
        self,
        prob,
        layout,
        theta_fixed,
        fixed_idx,
        weights,
        n_folds: int = 6,
        weighting: str = "regressor",
        recordings: Sequence[str] | None = None,
    ):
        self.prob, self.layout, self.weighting = prob, layout, weighting
        # the recording of each of the problem's segments (block_key's first column)
        self.recordings = None if recordings is None else list(recordings)
        self.theta_fixed, self.fixed_idx, self.weights = theta_fixed, fixed_idx, weights
        groups = np.unique(prob.group)
        self.n_folds = min(len(groups), n_folds)
        fold_of = {g: i % self.n_folds for i, g in enumerate(groups)}
        self.fold = np.array([fold_of[g] for g in prob.group])

    def _fit(self, train, effects: list[Candidate], theta_for_delay=None):
        free = free_columns(self.layout, effects, self.fixed_idx)
        with_delay = any(c.kind.input_dynamics for c in effects)
        return fit_equation_error(train, self.layout, free, self.theta_fixed, self.weights, with_delay, theta_for_delay)

    def physical_sign(self, base: list[Candidate], candidate: Candidate) -> bool:
        """Whether ``candidate``, fitted on all fit data beside ``base``, has a physical sign."""
        if not candidate.kind.physically_positive:
            return True
        th, _ = self._fit(self.prob, base + [candidate])
        return bool(th[self.layout.index(candidate.key)] > 0)

    def compare(self, base: list[Candidate], added: list[Candidate]) -> Evidence:
        """Evidence for ``base + added`` against ``base``."""
        sums0, sums1, energy, recordings = [], [], [], []
        for f in range(self.n_folds):
            train, test = self.prob.subset(self.fold != f), self.prob.subset(self.fold == f)
            th0, d0 = self._fit(train, base)
            th1, d1 = self._fit(train, base + added, th0)
            w = self.weights
            sums0.append(block_sums(test, th0, w, d0, None, momentum_norm(train, th0, w)))
            sums1.append(block_sums(test, th1, w, d1, th0, momentum_norm(train, th1, w)))
            energy.append(self._regressor_energy(test, added))
            recordings.append(self.recording_of(test))
        weights = None if self.weighting == "uniform" else block_weights(np.concatenate(energy))
        return Evidence.of_sums(np.concatenate(sums0), np.concatenate(sums1), weights, np.concatenate(recordings))

    def _regressor_energy(self, test, added: list[Candidate]) -> np.ndarray:
        """(blocks, len(added)): per block of ``test``, the energy of each added candidate's own
        weighted regressor. The input dynamics count every block alike: their column, the input's
        rate of change, is present wherever the input moves, and under feedback it is mostly the
        controller's answer to encoder steps, so its size says nothing of what a block can tell."""
        _, inv = np.unique(test.block_key, axis=0, return_inverse=True)
        n_blocks = int(inv.max()) + 1 if inv.size else 0
        out = np.zeros((n_blocks, len(added)))
        for i, c in enumerate(added):
            if c.kind.input_dynamics:
                out[:, i] = 1.0
                continue
            col = test.R[:, :, self.layout.index(c.key)]
            out[:, i] = np.bincount(
                inv.ravel(), weights=((col * self.weights[None]) ** 2).sum(axis=1), minlength=n_blocks
            )
        return out

    def recording_of(self, test) -> np.ndarray:
        """The recording (trajectory) of each block of ``test``, in :func:`block_sums`' order."""
        segment = np.unique(test.block_key, axis=0)[:, 0].astype(int)
        if self.recordings is None:
            return segment.astype(str).astype(object)
        return np.array([self.recordings[k] for k in segment], dtype=object)


def _representatives(pool, equivalents):
    """``pool`` with each group of candidates the data cannot tell apart reduced to its first
    member in library order (the specific mechanism), as a single pick would be."""
    out = []
    for c in pool:
        first = next(o for o in pool if o == c or o.key in equivalents.get(c.key, ()))
        if first == c:
            out.append(c)
    return out


def _best_pair(comparer, chosen, scores, pool, s: SearchSettings, equivalents=None):
    """The passing pair with the largest z among the ``pool`` largest-gain candidates, or None."""
    pool = _representatives(pool, equivalents or {})
    ranked = sorted(
        (c for c in pool if scores[c.key].improvement > 0 and comparer.physical_sign(chosen, c)),
        key=lambda c: -scores[c.key].improvement,
    )[: s.pair_pool]
    best = None
    for a, b in itertools.combinations(ranked, 2):
        whole = comparer.compare(chosen, [a, b])
        if not whole.passes(s.min_improvement, s.z_threshold):
            continue
        given_b = comparer.compare(chosen + [b], [a])
        given_a = comparer.compare(chosen + [a], [b])
        if min(given_b.z, given_a.z) < s.member_z_threshold or min(given_a.improvement, given_b.improvement) <= 0:
            continue
        if best is None or whole.z > best.pair_evidence.z:
            # sorted: a set's order would vary from run to run
            same = {o: m.key for m in (a, b) for o in sorted((equivalents or {}).get(m.key, ()))}
            best = Step((a, b), {a.key: given_b, b.key: given_a}, whole, same)
    return best


def _pick(passing, scores, remaining, equivalents):
    """The passing candidate with the largest z; among candidates these data cannot tell apart
    from it, the first in library order (the specific mechanism before the catch-all constant
    torque). Returns (pick, {equivalent key: pick key})."""
    best = max(passing, key=lambda c: scores[c.key].z)
    group = [c for c in remaining if c == best or c.key in equivalents.get(best.key, ())]
    pick = next(c for c in remaining if c in group and c in passing)
    return pick, {c.key: pick.key for c in group if c != pick}


def search(comparer: Comparer, testable: list[Candidate], s: SearchSettings, equivalents=None):
    """Forward selection that never stops at a failing candidate while another passes.

    Returns (accepted steps, the first round's evidence per candidate key).
    """
    chosen: list[Candidate] = []
    steps: list[Step] = []
    remaining = list(testable)
    first_round: dict[str, Evidence] = {}
    while remaining and len(chosen) < s.max_effects:
        scores = {c.key: comparer.compare(chosen, [c]) for c in remaining}
        first_round = first_round or dict(scores)
        passing = [
            c
            for c in remaining
            if scores[c.key].passes(s.min_improvement, s.z_threshold) and comparer.physical_sign(chosen, c)
        ]
        if passing:
            best, same = _pick(passing, scores, remaining, equivalents or {})
            steps.append(Step((best,), {best.key: scores[best.key]}, equivalents=same))
            chosen.append(best)
            remaining = [c for c in remaining if c != best and c.key not in same]
            continue
        if len(chosen) + 2 > s.max_effects:
            break
        pair = _best_pair(comparer, chosen, scores, remaining, s, equivalents)
        if pair is None:
            break
        steps.append(pair)
        chosen += list(pair.members)
        remaining = [c for c in remaining if c not in pair.members and c.key not in pair.equivalents]
    return steps, first_round
