"""PPO inside one ``jit`` on a gymnax-style env, and an adapter that runs its policy on Gymnasium.

A small PureJaxRL-style PPO for continuous actions (Equinox networks, Optax): collection with
``lax.scan`` over ``vmap``-ed copies of ``env.step``, GAE, clipped-ratio updates over shuffled
minibatches, all in one compiled function of a PRNG key. It talks to the env only through
gymnax's API (``reset``, ``step``, ``action_space``, ``observation_space``), so it trains the
functional envs of :mod:`furuta_gym.envs.functional` and gymnax's own envs alike.

Why here and not rejax: rejax 0.1.3 unpacks gymnax's old five-value ``step``, while gymnax
1.0.1 (the first release that allows jax >= 0.8.1) returns six (``terminated`` and ``truncated``
apart); this PPO uses the six: a truncated episode bootstraps from the value of
``info["final_observation"]``, which a time-limited swing-up (every episode truncated) needs.

:class:`GymnasiumPolicy` turns the trained :class:`Policy` into a NumPy callable, as a policy is
deployed on a Gymnasium env (the MuJoCo ground truth, say).
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float, PRNGKeyArray

from ._deprecated import deprecated_names

__all__ = [
    "PPOSettings",
    "Policy",
    "ObservationNormalizer",
    "ActorCritic",
    "train_ppo",
    "episode_returns",
    "GymnasiumPolicy",
]

_NET_DTYPE = jnp.float32  # networks in float32: the env's physics stays float64


@dataclasses.dataclass(frozen=True)
class PPOSettings:
    """PPO's settings (PureJaxRL's names); ``total_timesteps`` env steps in all."""

    total_timesteps: int = 1_000_000
    num_envs: int = 64
    num_steps: int = 128  # steps per copy between two updates
    update_epochs: int = 4
    num_minibatches: int = 8
    learning_rate: float = 3e-4
    anneal_lr: bool = True
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_eps: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    hidden: tuple[int, ...] = (64, 64)
    init_log_std: float = -0.5

    @property
    def num_updates(self) -> int:
        return max(1, self.total_timesteps // (self.num_envs * self.num_steps))


class ObservationNormalizer(eqx.Module):
    """Running mean and variance of the observations (merged batch by batch)."""

    mean: Float[Array, " d"]
    var: Float[Array, " d"]
    count: Float[Array, ""]

    @classmethod
    def empty(cls, size: int) -> "ObservationNormalizer":
        return cls(jnp.zeros(size, _NET_DTYPE), jnp.ones(size, _NET_DTYPE), jnp.asarray(1e-4, _NET_DTYPE))

    def __call__(self, obs):
        return jnp.clip((obs.astype(_NET_DTYPE) - self.mean) / jnp.sqrt(self.var + 1e-8), -10.0, 10.0)

    def update(self, batch) -> "ObservationNormalizer":
        batch = batch.reshape(-1, batch.shape[-1]).astype(_NET_DTYPE)
        n, mean, var = batch.shape[0], batch.mean(0), batch.var(0)
        total = self.count + n
        delta = mean - self.mean
        m2 = self.var * self.count + var * n + delta**2 * self.count * n / total
        return ObservationNormalizer(self.mean + delta * n / total, m2 / total, total)


class ActorCritic(eqx.Module):
    """A Gaussian policy (state-independent std) and a value function, separate MLPs."""

    actor: eqx.nn.MLP
    critic: eqx.nn.MLP
    log_std: Float[Array, " a"]

    def __init__(self, obs_size: int, action_size: int, hidden, init_log_std: float, key: PRNGKeyArray):
        k_actor, k_critic = jax.random.split(key)
        width, depth = (hidden[0], len(hidden)) if hidden else (0, 0)
        self.actor = eqx.nn.MLP(obs_size, action_size, width, depth, jax.nn.tanh, key=k_actor, dtype=_NET_DTYPE)
        self.critic = eqx.nn.MLP(obs_size, "scalar", width, depth, jax.nn.tanh, key=k_critic, dtype=_NET_DTYPE)
        self.log_std = jnp.full(action_size, init_log_std, _NET_DTYPE)

    def log_prob(self, obs, action):
        mean = self.actor(obs)
        z = (action - mean) / jnp.exp(self.log_std)
        return jnp.sum(-0.5 * z**2 - self.log_std - 0.5 * jnp.log(2 * jnp.pi))

    def entropy(self):
        return jnp.sum(self.log_std + 0.5 * jnp.log(2 * jnp.pi * jnp.e))


class Policy(eqx.Module):
    """The trained deterministic policy: normalised observation → the actor's mean, clipped to
    the action box. A pure function of its arrays (jit it, vmap it, save it with Equinox)."""

    net: ActorCritic
    normalizer: ObservationNormalizer
    low: Float[Array, " a"]
    high: Float[Array, " a"]

    def __call__(self, obs):
        return jnp.clip(self.net.actor(self.normalizer(obs)), self.low, self.high)


class _Transition(NamedTuple):
    obs: Array  # normalised, as the policy saw it
    action: Array  # unclipped sample
    log_prob: Array
    value: Array
    reward: Array
    terminated: Array
    done: Array
    next_value: Array  # value of the true next observation (before an autoreset)


class _Runner(NamedTuple):
    net: ActorCritic  # its arrays only (eqx.partition): the activation functions are not carried
    opt_state: Any
    normalizer: ObservationNormalizer
    env_state: Any
    obs: Array
    episode_return: Array
    key: Array


def _collect(env, params, config: PPOSettings, static, runner: _Runner):
    """``num_steps`` steps of every copy; the transitions and the returns of finished episodes."""
    space = env.action_space(params)
    low, high = jnp.asarray(space.low, _NET_DTYPE), jnp.asarray(space.high, _NET_DTYPE)
    step = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    def one(runner: _Runner, _):
        key, k_action, k_step = jax.random.split(runner.key, 3)
        net, norm = eqx.combine(runner.net, static), runner.normalizer
        obs = jax.vmap(norm)(runner.obs)
        mean = jax.vmap(net.actor)(obs)
        action = mean + jnp.exp(net.log_std) * jax.random.normal(k_action, mean.shape, _NET_DTYPE)
        keys = jax.random.split(k_step, config.num_envs)
        # in JAX's default float: a gymnax env keeps the action in its state (Pendulum-v1's
        # last_u), whose dtype must not change between reset and step for the autoreset
        env_action = jnp.clip(action, low, high).astype(float)
        next_obs, env_state, reward, terminated, truncated, info = step(keys, runner.env_state, env_action, params)
        done = terminated | truncated
        final = jax.vmap(norm)(info["final_observation"])
        transition = _Transition(
            obs,
            action,
            jax.vmap(net.log_prob)(obs, action),
            jax.vmap(net.critic)(obs),
            reward.astype(_NET_DTYPE),
            terminated,
            done,
            jax.vmap(net.critic)(final),
        )
        episode_return = runner.episode_return + reward
        finished = (jnp.where(done, episode_return, 0.0), done)
        runner = runner._replace(
            env_state=env_state, obs=next_obs, key=key, episode_return=jnp.where(done, 0.0, episode_return)
        )
        return runner, (transition, finished, runner.obs)

    runner, (batch, finished, raw_obs) = jax.lax.scan(one, runner, None, config.num_steps)
    runner = runner._replace(normalizer=runner.normalizer.update(raw_obs))
    returns, count = finished[0].sum(), finished[1].sum()
    return runner, batch, returns / jnp.maximum(count, 1), count


def _advantages(batch: _Transition, config: PPOSettings):
    """GAE over the rollout; a truncation bootstraps from the final observation's value."""

    def back(carry, t: _Transition):
        delta = t.reward + config.gamma * t.next_value * (1.0 - t.terminated) - t.value
        gae = delta + config.gamma * config.gae_lambda * (1.0 - t.done) * carry
        return gae, gae

    _, adv = jax.lax.scan(back, jnp.zeros_like(batch.value[0]), batch, reverse=True)
    return adv, adv + batch.value


def _loss(net: ActorCritic, batch: _Transition, adv, target, config: PPOSettings):
    log_prob = jax.vmap(net.log_prob)(batch.obs, batch.action)
    ratio = jnp.exp(log_prob - batch.log_prob)
    adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    actor = -jnp.minimum(ratio * adv, jnp.clip(ratio, 1 - config.clip_eps, 1 + config.clip_eps) * adv).mean()
    value = jax.vmap(net.critic)(batch.obs)
    clipped = batch.value + jnp.clip(value - batch.value, -config.clip_eps, config.clip_eps)
    critic = 0.5 * jnp.maximum((value - target) ** 2, (clipped - target) ** 2).mean()
    return actor + config.vf_coef * critic - config.ent_coef * net.entropy()


def _update(runner: _Runner, static, batch, adv, target, optimizer, config: PPOSettings) -> _Runner:
    """``update_epochs`` passes over the rollout in shuffled minibatches."""
    size = config.num_envs * config.num_steps
    flat = jax.tree_util.tree_map(lambda a: a.reshape(size, *a.shape[2:]), (batch, adv, target))
    grad = eqx.filter_grad(_loss)

    def epoch(carry, key):
        net, opt_state = carry
        order = jax.random.permutation(key, size).reshape(config.num_minibatches, -1)

        def minibatch(carry, idx):
            net, opt_state = carry
            b, a, t = jax.tree_util.tree_map(lambda x: x[idx], flat)
            grads = grad(eqx.combine(net, static), b, a, t, config)
            updates, opt_state = optimizer.update(eqx.filter(grads, eqx.is_array), opt_state, net)
            return (eqx.apply_updates(net, updates), opt_state), None

        return jax.lax.scan(minibatch, (net, opt_state), order)[0], None

    key, k_epochs = jax.random.split(runner.key)
    (net, opt_state), _ = jax.lax.scan(
        epoch, (runner.net, runner.opt_state), jax.random.split(k_epochs, config.update_epochs)
    )
    return runner._replace(net=net, opt_state=opt_state, key=key)


def _optimizer(config: PPOSettings):
    steps = config.num_updates * config.update_epochs * config.num_minibatches
    rate = optax.linear_schedule(config.learning_rate, 0.0, steps) if config.anneal_lr else config.learning_rate
    return optax.chain(optax.clip_by_global_norm(config.max_grad_norm), optax.adam(rate, eps=1e-5))


def train_ppo(env, params, config: PPOSettings, key: PRNGKeyArray):
    """Train from scratch; returns ``(policy, metrics)``, ``metrics["return"][i]`` the mean
    return of the episodes that ended during update ``i`` (NaN-free: 0 when none did) and
    ``metrics["episodes"][i]`` how many. Pure in ``key``: jit it with ``env`` and ``config``
    static (``eqx.filter_jit`` does), or vmap it over keys."""
    k_net, k_reset, k_run = jax.random.split(key, 3)
    obs_size = env.observation_space(params).shape[0]
    space = env.action_space(params)
    net = ActorCritic(obs_size, space.shape[0], config.hidden, config.init_log_std, k_net)
    optimizer = _optimizer(config)
    obs, env_state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, config.num_envs), params)
    arrays, static = eqx.partition(net, eqx.is_array)
    runner = _Runner(
        arrays,
        optimizer.init(arrays),
        ObservationNormalizer.empty(obs_size),
        env_state,
        obs,
        jnp.zeros(config.num_envs),
        k_run,
    )

    def update(runner, _):
        runner, batch, mean_return, episodes = _collect(env, params, config, static, runner)
        adv, target = _advantages(batch, config)
        return _update(runner, static, batch, adv, target, optimizer, config), (mean_return, episodes)

    runner, (returns, episodes) = jax.lax.scan(update, runner, None, config.num_updates)
    low, high = jnp.asarray(space.low, _NET_DTYPE), jnp.asarray(space.high, _NET_DTYPE)
    policy = Policy(
        eqx.combine(runner.net, static),
        runner.normalizer,
        jnp.broadcast_to(low, space.shape),
        jnp.broadcast_to(high, space.shape),
    )
    return policy, {"return": returns, "episodes": episodes}


def episode_returns(env, params, act, key: PRNGKeyArray, episodes: int, steps: int | None = None):
    """Returns of ``episodes`` episodes of ``steps`` steps (default: the params' horizon) from
    fresh resets, no autoreset: an episode that terminates scores nothing after it.
    ``act(obs, key) -> action``: a trained :class:`Policy` is ``lambda obs, key: policy(obs)``."""
    steps = int(params.max_steps_in_episode) if steps is None else steps

    def one(key):
        k_reset, k_run = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry, key):
            obs, state, total, live = carry
            k_act, k_step = jax.random.split(key)
            obs, state, reward, terminated, _ = env.step_env(k_step, state, act(obs, k_act), params)
            return (obs, state, total + jnp.where(live, reward, 0.0), live & ~terminated), None

        init = (obs, state, jnp.zeros(()), jnp.ones((), bool))
        return jax.lax.scan(body, init, jax.random.split(k_run, steps))[0][2]

    return jax.vmap(one)(jax.random.split(key, episodes))


class GymnasiumPolicy:
    """A trained :class:`Policy` as a NumPy callable ``obs -> action`` for a Gymnasium env of the
    same observation and action spaces (e.g. ``gym.make("furuta_gym/FurutaSwingUp-v0")``, the
    MuJoCo ground truth): one jitted call per step, the action in the env's dtype."""

    def __init__(self, policy: Policy, action_space):
        self.policy, self.dtype = policy, np.dtype(action_space.dtype)
        self._act = jax.jit(policy.__call__)

    def __call__(self, obs) -> np.ndarray:
        return np.asarray(self._act(jnp.asarray(obs)), dtype=self.dtype)


__getattr__ = deprecated_names(__name__)
