"""One optimiser step of a loss: the optimiser (Adam with weight decay, clipped), the step
function with its NaN guard, and its compiled (and, with JAX's cache on, stored) form; part of
:mod:`.train`."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optax

from . import _step_cache
from ._train_settings import TrainSettings
from .loss_kinds import LOSS_KINDS, StepSettings, loss_kind
from .losses import Normalization, Windows


def _tree_where(ok, new, old):
    return jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, old)


def _all_finite(tree) -> jnp.ndarray:
    leaves = jax.tree_util.tree_leaves(eqx.filter(tree, eqx.is_inexact_array))
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(l)) for l in leaves]))


def _build_optimizer(model, config: TrainSettings):
    trainable = model.trainable()
    decay_mask = model.decayed()
    params, _ = eqx.partition(model, trainable)
    mask = eqx.filter(decay_mask, trainable)  # same structure as params (None where not trainable)
    # unit step: the step function multiplies the update by the stage's learning rate, so stages
    # with different rates share one optimiser state and one compiled step
    adam = optax.adamw(1.0, weight_decay=config.weight_decay, mask=mask)
    opt = optax.chain(optax.clip_by_global_norm(config.grad_clip), adam) if config.grad_clip else adam
    # _make_step may store a step traced with this optimiser on disk: record what defines it
    _step_cache.register_optimizer(
        opt,
        f"adamw lr=1 (scaled per step) wd={config.weight_decay!r} "
        f"clip={config.grad_clip!r} mask={_step_cache.array_digest(mask)}",
    )
    return opt, trainable, params


def _step_function(
    static, optimizer, loss: str, config: TrainSettings, normalization: Normalization, augmentation_weight: float = 0.0
):
    """The optimiser step of ``loss``, not yet compiled: ``step(params, opt_state, traj_windows,
    integral_windows, lam, learning_rate) -> (params, opt_state, terms, ok)``."""
    kind = loss_kind(loss)
    settings = StepSettings(
        trajectory=dict(rtol=config.rtol, atol=config.atol, max_steps=config.max_steps),
        integral=dict(
            rule=config.quadrature,
            augmentation_part=config.augmentation_part,
            resolution_tolerance=config.resolution_tolerance,
            span=config.integral_span,
        ),
        normalization=normalization,
        augmentation_weight=augmentation_weight,
    )

    def step(params, opt_state, traj_b: Windows | None, int_b: Windows | None, lam, learning_rate):
        def objective(p):
            return kind.objective(eqx.combine(p, static), traj_b, int_b, lam, settings)

        (value, terms), grads = eqx.filter_value_and_grad(objective, has_aux=True)(params)
        ok = jnp.isfinite(value) & _all_finite(grads)
        updates, new_opt = optimizer.update(grads, opt_state, params)
        updates = jax.tree_util.tree_map(lambda u: learning_rate * u, updates)
        new_params = eqx.apply_updates(params, updates)
        params = _tree_where(ok, new_params, params)
        opt_state = _tree_where(ok, new_opt, opt_state)
        return params, opt_state, terms, ok

    return step


def _make_step(
    static, optimizer, loss: str, config: TrainSettings, normalization: Normalization, augmentation_weight: float = 0.0
):
    """:func:`_step_function` compiled (and, with JAX's persistent cache on, stored traced)."""
    step = _step_function(static, optimizer, loss, config, normalization, augmentation_weight)
    # level 0 skips LLVM's optimisations: a third less compile time for a slower step. Only
    # the steps with an ODE solve: an L_Iτ step compiles in seconds and runs many epochs
    fast = config.fast_compile and loss_kind(loss).uses_trajectory
    compiler_options = {"xla_backend_optimization_level": 0} if fast else None
    # equinox's overloads leave out the jax.jit keywords it passes on
    live_step = eqx.filter_jit(step, compiler_options=compiler_options)  # pyright: ignore[reportCallIssue]
    # with JAX's persistent compilation cache enabled, a later process loads the traced step from
    # disk instead of tracing it again (seconds for L_traj); see _step_cache
    cache_dir = _step_cache.step_cache_dir()
    described = _step_cache.optimizer_description(optimizer)
    if cache_dir is not None and described is not None:
        key = {
            "loss": loss,
            "normalization": normalization,
            "config": repr(config),
            "augmentation_weight": repr(float(augmentation_weight)),
            "optimizer": described,
            "static": _step_cache.array_digest(static),
        }
        # JAX takes compiler options on an outermost jit only: the step is exported without them
        # and the stored computation compiled with them
        return _step_cache.ExportedStep(
            live_step,
            key,
            cache_dir,
            compiler_options=compiler_options,
            export_step=eqx.filter_jit(step) if compiler_options else None,
        )
    return live_step


def training_step(
    model, config: TrainSettings, loss: str, normalization: Normalization = "momentum", augmentation_weight: float = 0.0
):
    """One optimiser step of ``loss`` for ``model``, built as :func:`train` builds it, with its
    starting parameters and optimiser state: ``(step, params, opt_state)``.

    ``step(params, opt_state, traj_windows, integral_windows, lam, learning_rate)`` returns
    ``(params, opt_state, losses, ok)``; ``loss`` is one of :data:`LOSSES` (``"itau"``: L_Iτ alone,
    ``traj_windows`` None). For benchmarks and experiments that time or probe the step itself."""
    if loss not in LOSS_KINDS:  # the registry as it is now: a loss defined after import counts
        raise ValueError(f"loss: expected one of {tuple(LOSS_KINDS)}, got {loss!r}")
    optimizer, trainable, params = _build_optimizer(model, config)
    _, static = eqx.partition(model, trainable)
    step = _make_step(static, optimizer, loss, config, normalization, augmentation_weight)
    return step, params, optimizer.init(params)
