"""Stacked equation-error problems of a set of segments, and the fits and sums taken on them."""

from __future__ import annotations

import numpy as np

from . import _fit
from ._library import Candidate

__all__ = ["Problem", "free_columns", "fit_equation_error", "block_sums", "momentum_norm"]


class Problem:
    """Stacked equation-error regressors of a set of segments.

    An interval in which a joint's encoder does not move is left out of that joint's equations
    (``keep`` = 0): at rest, dry friction holds the joint with whatever force balances the others
    (up to its breakaway level), so the equation says nothing about the modelled forces there.
    """

    def __init__(self, segments, c_input):
        self.segments = segments
        self.keep = np.concatenate([(~s.rest).astype(float) for s in segments])
        self.R = np.concatenate([s.residual_jacobian(c_input) for s in segments]) * self.keep[:, :, None]
        self.D = np.concatenate([s.D for s in segments]) * self.keep[:, :, None]
        self.dU = np.concatenate([s.dU for s in segments])
        self.c_input = c_input
        keys = []
        for k, s in enumerate(segments):
            keys.append(np.stack([np.full(s.block.shape, k), s.block], 1))
        self.block_key = np.concatenate(keys)
        self.group = np.concatenate([np.full(s.A.shape[0], s.group) for s in segments])

    def subset(self, mask):
        sub = object.__new__(Problem)
        sub.R, sub.D, sub.dU, sub.c_input = self.R[mask], self.D[mask], self.dU[mask], self.c_input
        sub.keep = self.keep[mask]
        sub.block_key, sub.group = self.block_key[mask], self.group[mask]
        sub.segments = None
        return sub

    def with_column(self, index: int, joint: int, column: np.ndarray) -> Problem:
        """This problem with parameter ``index``'s regressor on ``joint`` replaced by ``column``
        (N,) and zero on the other joints: the same candidate under another law."""
        out = object.__new__(Problem)
        out.__dict__.update(self.__dict__)
        out.R = self.R.copy()
        out.R[:, :, index] = 0.0
        out.R[:, joint, index] = column
        return out

    def delay_column(self, theta):
        """(N, n, 1): ∂(Z̄ − Ā)/∂d at d = 0 for the current input gain."""
        return (self.dU[:, None] * (self.c_input @ theta)[None, :] * self.keep)[:, :, None]


def free_columns(layout, chosen: list[Candidate], fixed_idx: set[int]):
    free = np.ones(layout.size, bool)
    free[len(layout.base) :] = False
    for c in chosen:
        if not c.kind.input_dynamics:  # the input dynamics have no column in θ
            free[layout.index(c.key)] = True
    for i in fixed_idx:
        free[i] = False
    return free


def fit_equation_error(prob, layout, free, theta_fixed, weights, with_delay: bool, theta_for_delay=None):
    scale = layout.typical_scale()
    if not with_delay:
        th, _ = _fit.ee_fit(prob.R, prob.D, free, theta_fixed, weights, scale)
        return th, 0.0
    th0, _ = _fit.ee_fit(prob.R, prob.D, free, theta_fixed, weights, scale)
    ref = th0 if theta_for_delay is None else theta_for_delay
    th, ex = _fit.ee_fit(prob.R, prob.D, free, theta_fixed, weights, scale, extra=prob.delay_column(ref))
    return th, float(ex[0])


def block_sums(prob, theta, weights, delay_coef=0.0, theta_for_delay=None, norm=None):
    """Per-block weighted residual sum of squares, divided by the model's ``norm`` (its mean
    ‖W D θ‖² on the training data) so that a candidate cannot win by shrinking the scale."""
    r = prob.R @ theta
    if delay_coef:
        r = r + prob.delay_column(theta if theta_for_delay is None else theta_for_delay)[:, :, 0] * delay_coef
    ss = ((r * weights[None]) ** 2).sum(axis=1)
    keys, inv = np.unique(prob.block_key, axis=0, return_inverse=True)
    out = np.bincount(inv.ravel(), weights=ss, minlength=len(keys))
    return out / (1.0 if norm is None else norm)


def momentum_norm(prob, theta, weights):
    return float(np.mean(((prob.D @ theta) * weights[None]) ** 2))
