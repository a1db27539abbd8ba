"""Automatic k_e pick by a short seeded closed-loop sweep on the design model itself.

The paper's k_e values (400 … 7000) are tied to its units and plant and don't carry over
(with 5 V the pump stalls at 60–75 % of the needed energy when k_e is small,
and works over a wide range once above that threshold). The rule, using nothing but the design
model:

1. sweep k_e over a geometric grid relative to the model's own scale (default
   ``default_k_e(model) · 2^(i/2 − 3)``, i = 0 … 10, i.e. 0.125 … 4 × the default; for the
   analytic model 617 … 19 755);
2. for each k_e, run the full swing-up → LQR controller on the design model from x0 = 0 and a few
   seeded starts near rest (``n_starts``), ``horizon`` seconds, 500 Hz, ZOH RK4;
3. a start counts when the pump brings the pendulum into the LQR's catch band — that is what
   k_e is responsible for; whether the model then balances in *its own* simulation depends on
   the model's accuracy near the upright, not on k_e (an undertrained DeLaN whose upright is not
   an equilibrium of itself would otherwise reject every gain);
4. the *stall threshold* k_min is the smallest grid value from which every start is caught for
   every larger grid value up to ``margin``·k_min;
5. pick k_e = ``margin`` · k_min (default 2): a factor of two above the stall threshold, so that
   dissipation the model doesn't know (friction, cable) still leaves enough pumping authority,
   and still inside the region that works on the model.

Raises ``ValueError`` if no grid value works on the design model (the model cannot swing itself
up under this voltage limit — a sign the model's energy landscape or input map is wrong).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..lagrangian import AbstractLagrangianSystem
from ._energy import default_k_e
from ._metrics import episode_metrics
from ._rollout import closed_loop

__all__ = ["GainSweep", "pick_k_e", "near_rest_starts"]

GRID_FACTORS = tuple(2.0 ** (i / 2 - 3) for i in range(11))


def near_rest_starts(n: int, seed: int, include_rest: bool = True) -> np.ndarray:
    """Seeded initial states near the hanging rest: α, β ~ U(±0.1 rad), α̇, β̇ ~ U(±0.2 rad/s);
    the first one is exactly x0 = 0 when ``include_rest``. Shape (n, 4)."""
    if n < 1:
        raise ValueError(f"number of starts must be >= 1, got {n}")
    rng = np.random.default_rng(seed)
    k = n - 1 if include_rest else n
    x = np.column_stack([rng.uniform(-0.1, 0.1, (k, 2)), rng.uniform(-0.2, 0.2, (k, 2))])
    return np.concatenate([np.zeros((1, 4)), x]) if include_rest else x


def near_upright_starts(n: int, seed: int) -> np.ndarray:
    """Seeded initial states near the upright, for a catch (LQR alone): α, β − π ~ U(±0.1 rad),
    α̇, β̇ ~ U(±0.2 rad/s), the spread of :func:`near_rest_starts` about the other equilibrium.
    Shape (n, 4)."""
    x = near_rest_starts(n, seed, include_rest=False)
    x[:, 1] += np.pi
    return x


@dataclasses.dataclass
class GainSweep:
    """Result of :func:`pick_k_e`: the chosen controller and the sweep behind it."""

    controller: Any
    k_e: float
    stall_threshold: float
    grid: tuple[float, ...]
    catch_rate: tuple[float, ...]  # per grid value: starts brought into the catch band
    success_rate: tuple[float, ...]  # per grid value: upright held 2 s (on the design model)
    median_time_to_upright: tuple[float, ...]  # s (nan when nothing succeeded)


def pick_k_e(
    build: Callable[[float], Any],
    model: AbstractLagrangianSystem,
    *,
    grid: Sequence[float] | None = None,
    n_starts: int = 5,
    horizon: float = 6.0,
    margin: float = 2.0,
    dt: float = 1.0 / 500.0,
    seed: int = 0,
) -> GainSweep:
    """Pick k_e on the design model (see the module docstring); ``build(k_e)`` makes a
    :class:`SwingUpLQR` with that gain; ``grid`` overrides the default relative grid."""
    if grid is None:
        k0 = default_k_e(model)
        grid = [k0 * f for f in GRID_FACTORS]
    grid = tuple(sorted(float(k) for k in grid))
    x0s = jnp.asarray(near_rest_starts(n_starts, seed))
    steps = int(round(horizon / dt))
    catches, rates, times = [], [], []
    run = None
    for k in grid:
        ctrl = build(k)
        if run is None:  # one compilation: the gain is a traced leaf of the controller pytree
            run = eqx.filter_jit(lambda c, xs: jax.vmap(lambda x0: closed_loop(c, model, x0, steps, dt=dt))(xs))
        r = run(ctrl, x0s)
        ms = [episode_metrics(r.xs[i], r.us[i], dt) for i in range(n_starts)]
        catches.append(float(np.mean(np.any(np.asarray(r.modes) > 0, axis=1))))
        rates.append(float(np.mean([m.success for m in ms])))
        t = [m.time_to_upright for m in ms if m.success and m.time_to_upright is not None]
        times.append(float(np.median(t)) if t else float("nan"))
    ok = np.asarray(catches) == 1.0
    k_min = None
    for i, k in enumerate(grid):
        upto = [j for j, kk in enumerate(grid) if k <= kk <= margin * k]
        if ok[upto].all() and (margin * k <= grid[-1] or i == len(grid) - 1):
            k_min = k
            break
    if k_min is None:
        raise ValueError(
            f"no k_e in {grid[0]:g}…{grid[-1]:g} swings the design model up from rest under this "
            f"voltage limit into the catch band (catch rates {catches}); check the model's "
            "potential and input map, or give k_e explicitly"
        )
    k_pick = min(margin * k_min, grid[-1])
    return GainSweep(build(k_pick), k_pick, k_min, grid, tuple(catches), tuple(rates), tuple(times))
