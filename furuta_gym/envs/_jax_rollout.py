"""The pure-JAX control step and rollout behind the batched env.

One *controlled step* is what a model-backed env does between two ``env.step`` calls, written as a
pure function of JAX arrays so it can be ``vmap``-ed over copies and ``scan``-ned over time:

1. clip the action to the actuator limit (the env's documented clipping);
2. integrate one control period with the input held (zero-order hold, fixed-step RK4 — the scheme
   of :func:`furuta_gym.simulate.rk4_zoh_step`, which is MuJoCo's RK4);
3. flag *divergence*: a next state that is non-finite or whose magnitude exceeds ``state_bound``
   (a learned model can blow up). A diverged copy keeps its last good state — it is *frozen* — so
   no NaN ever leaves this module, and the episode ends (``terminated``);
4. score the transition with the task's pure reward/termination functions.

:func:`rollout` runs a jittable policy through that step inside ``jax.lax.scan``, vmapped over a
batch of initial states, with no Python in the loop. Episodes do not restart inside a rollout: once
a copy's episode ends (task termination or divergence) it stays frozen and later steps are no-ops
(``done`` tells which steps were live).
"""

from __future__ import annotations

import functools
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, NamedTuple

import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ..effects import WithEffects
from ..lagrangian import AbstractLagrangianSystem
from ..models import Furuta, FurutaSharedTrig
from ..simulate import rk4_zoh_step, small_kernel_compiler_options

__all__ = [
    "DEFAULT_STATE_BOUND",
    "StepOutput",
    "Rollout",
    "is_diverged",
    "controlled_step",
    "stepping_model",
    "scan_closed_loop",
    "rollout",
    "chunk_bounds",
    "map_chunks",
]

#: Magnitude beyond which a state counts as "absurd" (diverged) when the caller gives no bound.
DEFAULT_STATE_BOUND = 1e6

RewardFn = Callable[[Array, Array, Array], Array]  # (x, u, x_next) -> scalar
TerminatedFn = Callable[[Array], Array]  # x_next -> bool


class StepOutput(NamedTuple):
    """One controlled step of one copy (leading batch axis when vmapped)."""

    state: Float[Array, " 2n"]  # next state; the previous one if the step diverged
    action: Float[Array, " m"]  # the action actually applied (after clipping)
    reward: Float[Array, ""]
    terminated: Bool[Array, ""]  # the task's termination or divergence
    diverged: Bool[Array, ""]


class Rollout(NamedTuple):
    """Trajectories of a batch of copies; ``N`` copies, ``T`` steps.

    ``states[:, t]`` is the state before step ``t`` (``states[:, 0] = x0s``). ``terminated[:, t]``
    and ``diverged[:, t]`` are True only at the step that ended the episode; ``done[:, t]`` is True
    from that step on. After the end a copy is frozen: its state is held, its action and reward are
    zero (no step is taken).
    """

    states: Float[Array, "N T+1 2n"]
    actions: Float[Array, "N T m"]
    rewards: Float[Array, "N T"]
    terminated: Bool[Array, "N T"]
    diverged: Bool[Array, "N T"]
    done: Bool[Array, "N T"]


def is_diverged(
    x: Float[Array, " 2n"], state_bound: float | tuple[float, ...] = DEFAULT_STATE_BOUND
) -> Bool[Array, ""]:
    """True when the state is non-finite or any component exceeds ``state_bound`` in magnitude
    (one bound, or a tuple of one per component: ``inf`` leaves a component, e.g. an angle, to
    the finiteness test; see :func:`furuta_gym.envs._tasks.divergence_bounds`)."""
    bound = jnp.asarray(state_bound, dtype=x.dtype)
    return jnp.logical_not(jnp.all(jnp.isfinite(x))) | jnp.any(jnp.abs(x) > bound)


def _static_bound(state_bound) -> float | tuple[float, ...]:
    """A hashable (jit-static) form of a scalar or per-component state bound."""
    if np.ndim(state_bound):
        return tuple(float(b) for b in np.asarray(state_bound).ravel())
    return float(state_bound)


def _zero_reward(x, u, x_next):
    return jnp.zeros((), dtype=x.dtype)


def _never_terminated(x_next):
    return jnp.zeros((), dtype=bool)


def stepping_model(model):
    """The model :func:`controlled_step` integrates: the analytic Furuta (also under a ``WithEffects``
    plant) as :class:`~furuta_gym.models.FurutaSharedTrig`, the same physics with its trig
    evaluated once per RK4 stage (equal to round-off, about twice the steps/s under XLA:CPU);
    other models as given."""
    base = model.base if isinstance(model, WithEffects) else model
    if type(base) is not Furuta:  # a subclass may redefine the physics: leave it alone
        return model
    shared = FurutaSharedTrig(params=base.params)
    return eqx.tree_at(lambda m: m.base, model, shared) if isinstance(model, WithEffects) else shared


def controlled_step(
    system: AbstractLagrangianSystem,
    x: Float[Array, " 2n"],
    u: Float[Array, " m"],
    *,
    dt: float,
    substeps: int = 1,
    action_limit: float | None = None,
    state_bound: float | tuple[float, ...] = DEFAULT_STATE_BOUND,
    reward_fn: RewardFn | None = None,
    terminated_fn: TerminatedFn | None = None,
) -> StepOutput:
    """One env step of one copy as a pure JAX function (see the module docstring).

    A non-finite action counts as a divergence (the env itself raises on one; a jitted policy
    cannot, so its copy is frozen and flagged instead). The reward of a diverged step is computed
    at the frozen state, so it is finite.
    """
    reward_fn = _zero_reward if reward_fn is None else reward_fn
    terminated_fn = _never_terminated if terminated_fn is None else terminated_fn
    u = jnp.reshape(jnp.asarray(u, dtype=x.dtype), (system.spec.n_inputs,))
    bad_action = jnp.logical_not(jnp.all(jnp.isfinite(u)))
    if action_limit is not None:
        u = jnp.clip(u, -action_limit, action_limit)
    u = jnp.where(bad_action, jnp.zeros_like(u), u)
    x_new = rk4_zoh_step(stepping_model(system), x, u, dt, substeps)
    diverged = bad_action | is_diverged(x_new, state_bound)
    x_next = jnp.where(diverged, x, x_new)
    reward = jnp.asarray(reward_fn(x, u, x_next), dtype=x.dtype)
    terminated = jnp.asarray(terminated_fn(x_next), dtype=bool) | diverged
    return StepOutput(x_next, u, reward, terminated, diverged)


def rollout(
    system: AbstractLagrangianSystem,
    policy: Callable,
    x0s: Float[Array | np.ndarray, "N 2n"] | Float[Array | np.ndarray, " 2n"],
    steps: int,
    *,
    dt: float,
    substeps: int = 1,
    action_limit: float | None = None,
    state_bound: float | tuple[float, ...] = DEFAULT_STATE_BOUND,
    reward_fn: RewardFn | None = None,
    terminated_fn: TerminatedFn | None = None,
    observation_fn: Callable[[Array], Array] | None = None,
    policy_state: Any = None,
    chunks: int | None = None,
) -> Rollout:
    """Run ``policy`` in closed loop from every initial state, entirely inside ``lax.scan``.

    ``policy`` is a jittable callable (a function, an Equinox module, a controller): stateless
    ``policy(obs) -> action`` or, when ``policy_state`` is given, stateful
    ``policy(policy_state, obs) -> (action, new_policy_state)`` (every copy starts from the same
    ``policy_state``). A controller from :mod:`furuta_gym.controllers` (``step`` + ``init_state``)
    is accepted as is. ``obs = observation_fn(x)`` (default: the raw state, as the envs observe).
    Actions are clipped to ``±action_limit`` as the env does. ``x0s`` of shape ``(N, 2n)`` gives a
    batch (vmapped); a single state ``(2n,)`` gives unbatched outputs.

    Compiled once per (structure of system and policy, ``steps``, options); new weights of the same
    model reuse the compilation. Pass module-level functions for ``reward_fn`` / ``terminated_fn`` /
    ``observation_fn`` (a new lambda each call recompiles).

    ``chunks``: the batch runs as this many contiguous sub-batches, concurrently from threads
    (XLA:CPU runs separate executions side by side, while one execution of a small-network model
    keeps about one core busy; docs/batched.md "Speed").
    Default: one per core from 512 copies on, else 1; always 1 when called inside a JAX
    transformation (jit, vmap), where the rollout becomes part of the caller's computation. No
    copy's numbers depend on it.

    Returns a :class:`Rollout` (states, actions, rewards, terminated/diverged/done flags).
    """
    steps, x0s = _checked_rollout_arguments(system, x0s, steps, substeps, dt)
    single = x0s.ndim == 1
    step_fn, policy_state, stateful = _as_policy(policy, policy_state)
    batch = x0s[None] if single else x0s
    traced = any(
        isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves((system, step_fn, batch, policy_state))
    )
    chunks = _chunk_count(chunks, batch.shape[0])
    # inside someone else's jit, the rollout is part of their computation: a nested jit may not
    # carry compiler options
    run = functools.partial(
        _rollout_vmapped if traced else _rollout_batch,
        system,
        step_fn,
        policy_state=policy_state,
        steps=steps,
        dt=float(dt),
        substeps=int(substeps),
        action_limit=None if action_limit is None else float(action_limit),
        state_bound=_static_bound(state_bound),
        reward_fn=reward_fn,
        terminated_fn=terminated_fn,
        observation_fn=observation_fn,
        stateful=stateful,
    )
    out = _run_in_chunks(run, batch, 1 if traced else chunks)
    return Rollout(*(a[0] for a in out)) if single else out


def _run_in_chunks(run: Callable[[Array], Any], batch: Array, chunks: int) -> Rollout:
    """``run(batch)``, as ``chunks`` contiguous sub-batches run concurrently from threads."""
    if chunks == 1:
        out = run(batch)
    else:
        with ThreadPoolExecutor(chunks, thread_name_prefix="furuta_gym-rollout") as pool:
            parts = map_chunks(lambda a, b: run(batch[a:b]), batch.shape[0], chunks, pool)
        out = Rollout(*(jnp.concatenate(fields, axis=0) for fields in zip(*parts, strict=True)))
    assert isinstance(out, Rollout)
    return out


def _checked_rollout_arguments(system, x0s, steps, substeps, dt):
    """(steps, x0s as a float array) after checking them against the system."""
    steps = int(steps)
    if steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps}")
    if int(substeps) < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps}")
    if not dt > 0:
        raise ValueError(f"dt must be a positive control period in seconds, got {dt}")
    x0s = jnp.asarray(x0s, dtype=float)
    n_state = 2 * system.spec.n_dof
    if x0s.ndim not in (1, 2) or x0s.shape[-1] != n_state:
        raise ValueError(
            f"x0s must have shape (N, {n_state}) or ({n_state},) for {system.spec.name!r} "
            f"(state {system.spec.state_names}), got {tuple(x0s.shape)}"
        )
    return steps, x0s


def _chunk_count(chunks, n: int) -> int:
    """Sub-batches of a rollout of ``n`` copies: one per core from 512 copies on, else 1."""
    if chunks is None:
        return (os.cpu_count() or 1) if n >= 512 else 1
    if isinstance(chunks, bool) or not isinstance(chunks, (int, np.integer)) or not 1 <= chunks <= n:
        raise ValueError(f"chunks must be an integer from 1 to the number of copies ({n}), got {chunks!r}")
    return int(chunks)


def chunk_bounds(n: int, chunks: int) -> np.ndarray:
    """Edges of ``chunks`` contiguous, near-equal sub-batches of ``n`` copies."""
    return np.linspace(0, n, chunks + 1).round().astype(int)


def map_chunks(fn: Callable[[int, int], Any], n: int, chunks: int, pool=None) -> list:
    """``fn(a, b)`` for each sub-batch ``[a, b)`` of :func:`chunk_bounds`, in order; concurrently
    on ``pool`` (a thread pool: JAX releases the GIL while XLA runs) or, without one, in turn."""
    edges = chunk_bounds(n, chunks)
    spans = list(zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True))
    if pool is None:
        return [fn(a, b) for a, b in spans]
    return list(pool.map(lambda span: fn(*span), spans))


def _as_policy(policy, policy_state):
    """(callable, initial policy state, stateful?) for a function, module or controller.

    A controller (``furuta_gym.controllers``: ``step(state, obs) -> (action, state)`` and
    ``init_state()``) runs through its pure ``step``; its ``__call__`` is the NumPy-side policy and
    cannot be traced.
    """
    step = getattr(policy, "step", None)
    init_state = getattr(policy, "init_state", None)
    if callable(step) and callable(init_state):
        if policy_state is None:
            policy_state = init_state()
        # a bound method of an Equinox module is itself a pytree, so weights stay traced arguments
        return step, policy_state, True
    if not callable(policy):
        raise ValueError(
            f"policy must be a jittable callable obs -> action, (state, obs) -> (action, state) "
            f"with policy_state=..., or a controller with step/init_state; got {type(policy).__name__}"
        )
    return policy, policy_state, policy_state is not None


def _observation(observer, observation_fn, x0):
    """(initial sensor state, ``observe(x, z) -> (obs, z)``): the observer's, or a memoryless
    ``observation_fn`` (default: the state itself) with an empty sensor state."""
    if observer is not None:
        return observer.init(x0), observer.observe
    identity = (lambda x: x) if observation_fn is None else observation_fn

    def observe(x, z):
        return identity(x), z

    return (), observe


def scan_closed_loop(
    system,
    policy,
    x0,
    policy_state,
    *,
    steps: int,
    dt: float,
    substeps: int = 1,
    action_limit: float | None = None,
    state_bound: float | tuple[float, ...] = DEFAULT_STATE_BOUND,
    reward_fn: RewardFn | None = None,
    terminated_fn: TerminatedFn | None = None,
    observation_fn: Callable[[Array], Array] | None = None,
    observer: Any = None,
    stateful: bool = True,
    record: bool = False,
) -> Any:
    """The one closed loop of the package: one copy, ``steps`` controlled steps in ``lax.scan``.

    Each step observes the state, asks the policy, and takes :func:`controlled_step`; after an
    episode end (task termination or divergence) the copy, its policy state and its observer state
    are frozen. The observation is ``observation_fn(x)`` (default: the state) or, for a sensor
    with memory (e.g. a derivative filter), ``observer``: an object with ``init(x0) -> z0`` and
    ``observe(x, z) -> (obs, z)``. Returns a :class:`Rollout` of this copy and, with
    ``record=True``, also the observations the policy saw and its state after each step (what
    :func:`furuta_gym.controllers.closed_loop` reports). Used by :func:`rollout` (vmapped, jitted)
    and by the controllers' ``closed_loop``; jit and vmap it as they do.
    """
    z0, observe = _observation(observer, observation_fn, x0)

    def freeze(live, new, old):
        return jax.tree_util.tree_map(lambda a, b: jnp.where(live, a, b), new, old)

    def body(carry, _):
        x, done, pstate, z = carry
        obs, new_z = observe(x, z)
        action, new_pstate = policy(pstate, obs) if stateful else (policy(obs), pstate)
        out = controlled_step(
            system,
            x,
            action,
            dt=dt,
            substeps=substeps,
            action_limit=action_limit,
            state_bound=state_bound,
            reward_fn=reward_fn,
            terminated_fn=terminated_fn,
        )
        live = jnp.logical_not(done)
        x_next = jnp.where(live, out.state, x)
        # a frozen copy keeps its policy and sensor state too, so nothing it carries can drift to NaN
        new_pstate, new_z = freeze(live, new_pstate, pstate), freeze(live, new_z, z)
        record_step = _step_record(live, done, x_next, out)
        if record:
            record_step = (*record_step, obs, new_pstate)
        return (x_next, done | out.terminated, new_pstate, new_z), record_step

    init = (x0, jnp.zeros((), dtype=bool), policy_state, z0)
    _, records = jax.lax.scan(body, init, None, length=steps)
    xs, us, rs, term, div, done = records[:6]
    out = Rollout(jnp.concatenate([x0[None], xs], axis=0), us, rs, term, div, done)
    return (out, *records[6:]) if record else out


def _step_record(live, done, x_next, out: StepOutput) -> tuple:
    """What a scanned step records: the next state, the action and reward (0 once frozen), the
    episode's end flags (raised on the step that ends it) and whether it is done."""
    return (
        x_next,
        jnp.where(live, out.action, jnp.zeros_like(out.action)),
        jnp.where(live, out.reward, jnp.zeros_like(out.reward)),
        live & out.terminated,
        live & out.diverged,
        done | out.terminated,
    )


def _rollout_vmapped(system, policy, x0s, *, policy_state, **options):
    return jax.vmap(lambda x0: scan_closed_loop(system, policy, x0, policy_state, **options))(x0s)


_ROLLOUT_JIT: list = []


def _rollout_batch(*args, **kwargs):
    """The jitted rollout, built on first use (its compiler options are probed lazily, not at
    import) with the model-step options of :func:`furuta_gym.simulate.small_kernel_compiler_options`."""
    if not _ROLLOUT_JIT:
        _ROLLOUT_JIT.append(
            # equinox's overloads leave out the jax.jit keywords it passes on
            eqx.filter_jit(_rollout_vmapped, compiler_options=small_kernel_compiler_options())  # pyright: ignore[reportCallIssue]
        )
    return _ROLLOUT_JIT[0](*args, **kwargs)
