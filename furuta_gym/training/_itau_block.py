"""Epochs of a full-batch L_Iτ-alone stage run as one compiled loop.

Such an epoch is one optimiser step on every integral window, milliseconds of arithmetic. Run
one at a time from Python, the epoch's host work (drawing and gathering its window order,
dispatching the step, reading its loss back, writing the training state) cost several times the
step itself. A block runs ``n`` epochs inside one ``lax.fori_loop``: the windows stay on the
device, each epoch gathers them in its own order (the order the per-epoch loop draws), and the
loop carries the parameters, the optimiser state and the stage's lowest-loss iterate
(``keep_best_itau``). The trip count is an argument, so one compiled block serves every block
length up to its capacity and each epoch runs the same compiled body whatever the partition:
a run stopped and resumed between any two blocks gives the model of a run never stopped, bit
for bit.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .losses import Windows

__all__ = ["CAPACITY", "BlockResult", "ItauBlock"]

#: epochs one compiled block can run; a block's length is chosen per call up to it
CAPACITY = 256


class BlockResult(NamedTuple):
    """What ``n`` epochs gave: the parameters and optimiser state after them, each epoch's loss
    terms and whether its step was taken (``terms`` arrays of length ``n``, ``ok`` likewise),
    and the lowest-loss iterate seen (``best_after`` −1 if none improved on the one passed in)."""

    params: Any
    opt_state: Any
    terms: dict[str, np.ndarray]
    ok: np.ndarray
    best_params: Any
    best_total: float
    best_after: int


class ItauBlock:
    """``n`` epochs of ``step`` (:func:`furuta_gym.training.train._step_function`'s, L_Iτ alone)
    on all of ``windows``, compiled once."""

    def __init__(self, step: Callable, windows: Windows, seed: int, keep_best: bool):
        self.windows = Windows(*(jnp.asarray(a) for a in windows))
        self.seed, self.keep_best = seed, keep_best
        self._compiled = eqx.filter_jit(_block_loop(step, keep_best))

    def order(self, epoch: int) -> np.ndarray:
        """The epoch's window order: the first permutation the per-epoch loop draws for it."""
        return np.random.default_rng([self.seed, epoch]).permutation(self.windows.n_windows)

    def __call__(self, params, opt_state, lam, first_epoch: int, learning_rates, best=None) -> BlockResult:
        """Epochs ``first_epoch`` … ``first_epoch + len(learning_rates) − 1``; ``best`` the stage's
        lowest-loss iterate so far ``(total, after, params)`` or None."""
        n = len(learning_rates)
        if not 1 <= n <= CAPACITY:
            raise ValueError(f"a block runs 1 to {CAPACITY} epochs, got {n}")
        orders = np.zeros((CAPACITY, self.windows.n_windows), dtype=np.int32)
        rates = np.zeros(CAPACITY)
        for i in range(n):
            orders[i] = self.order(first_epoch + i)
            rates[i] = learning_rates[i]
        best_total, best_after, best_params = best if best is not None else (np.inf, -1, params)
        out = self._compiled(
            params,
            opt_state,
            self.windows,
            jnp.asarray(orders),
            jnp.asarray(rates),
            jnp.asarray(lam),
            jnp.asarray(n),
            jnp.asarray(first_epoch),
            (jnp.asarray(float(best_total)), jnp.asarray(int(best_after)), best_params),
        )
        params, opt_state, terms, ok, (best_total, best_after, best_params) = out
        return BlockResult(
            params,
            opt_state,
            {k: np.asarray(v)[:n] for k, v in terms.items()},
            np.asarray(ok)[:n],
            best_params,
            float(best_total),
            int(best_after),
        )


def _block_loop(step: Callable, keep_best: bool) -> Callable:
    def block(params, opt_state, windows: Windows, orders, rates, lam, n, first_epoch, best):
        shapes = jax.eval_shape(step, params, opt_state, None, windows, lam, rates[0])[2]
        terms0 = {k: jnp.zeros((CAPACITY, *s.shape), s.dtype) for k, s in shapes.items()}
        ok0 = jnp.zeros(CAPACITY, dtype=bool)

        def epoch(i, carry):
            params, opt_state, terms, ok, (best_total, best_after, best_params) = carry
            new_params, new_opt, t, took = step(params, opt_state, None, windows.take(orders[i]), lam, rates[i])
            if keep_best:  # the iterate this epoch started from, scored by this epoch's loss
                better = took & (t["total"] < best_total)
                best_params = jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), params, best_params)
                best_total = jnp.where(better, t["total"], best_total)
                best_after = jnp.where(better, first_epoch + i, best_after)
            terms = {k: terms[k].at[i].set(v) for k, v in t.items()}
            return new_params, new_opt, terms, ok.at[i].set(took), (best_total, best_after, best_params)

        return jax.lax.fori_loop(0, n, epoch, (params, opt_state, terms0, ok0, best))

    return block
