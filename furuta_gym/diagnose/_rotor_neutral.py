"""Method step 11's moving neutral (issue 64): the play operator run over a log gives each
trajectory's and each window's starting neutral of a cable whose rest moves, and the open-loop
windows are predicted with that neutral dragged by the predicted motion after each step
(:class:`furuta_gym.effects.WithNeutral`, advanced as the MuJoCo plant advances it)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..effects import WithNeutral, dragged_neutral, play_operator
from ..lagrangian import forward_dynamics_with_dry_friction
from ..simulate import rk4_zoh_step
from ..systems import get_spec
from . import _fit, _windows


def neutral_paths(trajs, j: int, play: float, starts=None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{trajectory name: (t, neutral after each sample)}: the play operator run over joint ``j``
    of each of ``trajs``, from its first neutral q_j(0) + play·ρ (``starts``: ρ ∈ [−1, 1] per
    trajectory; None: the history's, :func:`carried_starts`)."""
    starts = carried_starts(trajs, j, play) if starts is None else starts
    out = {}
    for tr, rho in zip(trajs, starts, strict=True):
        q = np.asarray(tr.q[:, j], float)
        out[tr.name] = (np.asarray(tr.t), play_operator(q, play, q[0] + play * float(rho)))
    return out


def carried_starts(trajs, j: int, play: float, first: float = 0.0) -> np.ndarray:
    """ρ of each trajectory's first neutral as the recorded history implies it: the first
    trajectory's at ρ ``first`` (0: a log starts with the joint resting on its neutral), each
    next one's where the last left it, dragged by a hand that carried the joint between them."""
    out, r = [first], None
    for tr, nxt in zip(trajs[:-1], trajs[1:], strict=True):
        q = np.asarray(tr.q[:, j], float)
        r = play_operator(q, play, q[0] + play * out[-1])[-1]
        q1 = float(nxt.q[0, j])
        out.append((float(dragged_neutral(r, q1, play)) - q1) / play if play > 0 else 0.0)
    return np.asarray(out)


def _window_neutrals(segs, length: int, paths) -> np.ndarray:
    """Each window's starting neutral, in :func:`._windows.make_windows`' order."""
    out = []
    for s in segs:
        t, r = paths[s.name.rsplit("[", 1)[0]]
        offset = int(np.searchsorted(t, s.t[0] - 1e-9 * s.dt))
        out += [r[offset + start] for start in range(0, s.q.shape[0] - length, length)]
    return np.asarray(out)


def _predictor(layout, dt: float, length: int, substeps: int, j: int, start_iterations: int):
    """Open-loop windows of the library model plus a cable with memory on joint ``j``: its
    neutral carried through the window, dragged after each step (θ, (k, w), x0, u, q, r0)."""
    n = get_spec(layout.system).n_dof
    h = dt / substeps

    def one(theta, cable, x, u, q_measured, r0):
        base = layout.model(theta, dry_friction=False)

        def positions(v, x, u):
            def step(carry, u_k):
                xk, r = carry
                model = WithNeutral(base, r, cable[0], cable[1], j)

                def field(y, uu):
                    limit = layout.dry_friction_limit(theta, y[n:])
                    qdd = forward_dynamics_with_dry_friction(model, limit, y[:n], y[n:], uu, h)
                    return jnp.concatenate([y[n:], qdd])

                x1 = rk4_zoh_step(model, xk, u_k, dt, substeps, field)
                return (x1, dragged_neutral(r, x1[j], cable[1], jnp)), x1[:n]

            return jax.lax.scan(step, (jnp.concatenate([x[:n], v]), r0), u)[1]

        return _windows._refined_positions(positions, x[n:], x, u, q_measured, start_iterations)

    key = ("cable", j, start_iterations)
    return _fit._compiled("predict_law", layout, dt, length, substeps, *key, build=lambda: jax.jit(jax.vmap(one)))


def predict(layout, thetas, cables, win: _windows.Windows, r0s, substeps: int, j: int, start_iterations: int):
    """(K, W, L, n) predictions under each (θ, cable, per-window neutrals) of ``thetas`` (K, P),
    ``cables`` (K, 2), ``r0s`` (K, W), batched as :func:`._windows.predict_windows_at` does."""
    fn = _predictor(layout, win.dt, win.length, substeps, j, start_iterations)
    thetas, cables, r0s = (np.asarray(a, dtype=float) for a in (thetas, cables, r0s))
    W = win.x0.shape[0]
    which, window = np.divmod(np.arange(len(thetas) * W), W)
    out = []
    for s in range(0, which.size, _windows._BATCH):
        real = np.arange(s, min(s + _windows._BATCH, which.size))
        pad = np.concatenate([real, np.full(_windows._BATCH - real.size, real[-1])])
        k, w = which[pad], window[pad]
        args = (thetas[k], cables[k], win.x0[w], win.us[w], win.q[w], r0s[k, w])
        out.append(np.asarray(fn(*map(jnp.asarray, args)))[: real.size])
    return np.concatenate(out).reshape(len(thetas), *win.q.shape)


def square_sums(pred: np.ndarray, measured: np.ndarray) -> np.ndarray:
    ss = np.sum((pred - measured) ** 2, axis=(1, 2))
    return np.where(np.isfinite(ss), ss, np.inf)
