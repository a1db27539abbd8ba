"""Batched model-backed env and the pure-JAX rollout (issue 4, item 3).

Compiles are the cost here, so every jitted object is built once per module and reused.
"""

from __future__ import annotations

import sys
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym.envs._jax_rollout import controlled_step, rollout
from furuta_gym.lagrangian import AbstractLagrangianSystem, SystemSpec
from furuta_gym.models import NMSD, Furuta, NMSDParameters
from furuta_gym.simulate import rollout_zoh

DT = 0.002


def lqr_like(obs):
    """A jittable memoryless feedback that saturates the 5 V limit at times (clipping matters)."""
    return jnp.array([8.0 * jnp.sin(obs[1]) - 0.2 * obs[2] + 0.5 * obs[3]])


class CountingPolicy:
    """A stateful policy: the action ramps with the number of steps taken (tests the carry)."""

    def __call__(self, count, obs):
        return jnp.array([0.01 * count]), count + 1


class BlowUp(AbstractLagrangianSystem):
    """A "learned model" gone wrong: a softening cubic spring that explodes in finite time.

    Starting at rest at p = 0 it stays exactly there; anywhere else beyond ~1 m it reaches inf/NaN
    within a fraction of a second, the way an over-fitted network can.
    """

    spec: ClassVar[SystemSpec] = NMSD().spec

    def mass_matrix(self, q):
        return jnp.eye(1)

    def potential(self, q):
        return -25.0 * q[0] ** 4

    def nonconservative_force(self, q, qd):
        return jnp.zeros(1)

    def input_force(self, q, qd, u):
        return u[:1]


@pytest.fixture(scope="module")
def furuta_rollout():
    x0s = jnp.array([[0.0, 0.05, 0.0, 0.0], [0.3, 3.0, -1.0, 0.5], [-0.2, 2.9, 2.0, -3.0]])
    return x0s, rollout(Furuta(), lqr_like, x0s, 400, dt=DT, substeps=2, action_limit=5.0)


def test_rollout_replays_as_open_loop_zoh(furuta_rollout):
    """The scan/vmap rollout is the policy in closed loop with the env's clipping and ZOH RK4."""
    x0s, out = furuta_rollout
    assert out.states.shape == (3, 401, 4) and out.actions.shape == (3, 400, 1)
    # the policy saw the state of its own step and its action was clipped to ±5 V
    policy_u = jax.vmap(jax.vmap(lqr_like))(out.states[:, :-1])
    np.testing.assert_allclose(out.actions, jnp.clip(policy_u, -5.0, 5.0), rtol=0, atol=1e-12)
    assert np.max(np.abs(policy_u)) > 5.0  # clipping was exercised
    replay = jax.jit(jax.vmap(lambda x0, us: rollout_zoh(Furuta(), x0, us, DT, 2)))
    np.testing.assert_allclose(out.states, replay(x0s, out.actions), rtol=0, atol=1e-12)
    assert not out.done.any() and not out.diverged.any()


def test_rollout_single_state_and_stateful_policy():
    x0 = jnp.array([0.1, 0.0])
    out = rollout(NMSD(), CountingPolicy(), x0, 50, dt=0.01, policy_state=jnp.array(0.0))
    assert out.states.shape == (51, 2)
    np.testing.assert_allclose(out.actions[:, 0], 0.01 * np.arange(50), atol=1e-15)
    np.testing.assert_allclose(out.states, rollout_zoh(NMSD(), x0, out.actions, 0.01, 1), atol=1e-12)


def test_diverging_copy_is_frozen_flagged_and_isolated():
    """One copy of a blown-up model diverges; no NaN leaks and the other copies are untouched."""
    x0s = jnp.array([[0.0, 0.0], [2.0, 0.0], [0.0, 0.0]])
    zero = lambda obs: jnp.zeros(1)  # noqa: E731
    out = jax.tree_util.tree_map(np.asarray, rollout(BlowUp(), zero, x0s, 200, dt=0.01))
    assert np.all(np.isfinite(out.states)) and np.all(np.isfinite(out.rewards))
    assert out.diverged[1].sum() == 1 and not out.diverged[[0, 2]].any()
    t_div = int(np.argmax(out.diverged[1]))
    assert out.terminated[1, t_div] and out.done[1, t_div:].all() and not out.done[1, :t_div].any()
    # frozen at the last good state, which was already large (it was blowing up)
    assert np.all(out.states[1, t_div + 1 :] == out.states[1, t_div])
    assert abs(out.states[1, t_div, 0]) > 2.0
    np.testing.assert_array_equal(out.states[[0, 2]], 0.0)
    # the step function alone, on a NaN action, also freezes instead of propagating it
    step = controlled_step(NMSD(), jnp.array([0.1, 0.0]), jnp.array([jnp.nan]), dt=0.01)
    assert bool(step.diverged) and np.all(np.isfinite(step.state))


# ---------------------------------------------------------------------------------------------
# the batched env against single envs
# ---------------------------------------------------------------------------------------------

FURUTA_ID = "furuta_gym/Furuta-v0"
NMSD_ID = "furuta_gym/NMSD-v0"


def _max_diff(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))


def _assert_same_step(batched, reference, atol=1e-12, rtol=1e-12):
    """obs, reward, terminated, truncated and every info entry agree (to round-off: a vmapped
    kernel may fuse differently from the single env's, so 1e-12 absolute or relative — a
    blowing-up copy reaches 1e3)."""
    obs, rew, term, trunc, info = batched
    obs_r, rew_r, term_r, trunc_r, info_r = reference
    np.testing.assert_allclose(obs, obs_r, rtol=rtol, atol=atol)
    np.testing.assert_allclose(rew, rew_r, rtol=rtol, atol=atol)
    np.testing.assert_array_equal(term, term_r)
    np.testing.assert_array_equal(trunc, trunc_r)
    assert set(info) == set(info_r)
    for key in info_r:
        np.testing.assert_allclose(
            np.asarray(info[key], dtype=float),
            np.asarray(info_r[key], dtype=float),
            rtol=rtol,
            atol=atol,
            err_msg=key,
        )


@pytest.fixture(scope="module")
def furuta_pair():
    """A batched env and Gymnasium's SyncVectorEnv of single envs, same settings (25-step episodes)."""
    import gymnasium as gym

    from furuta_gym.envs.vector import FurutaVectorEnv

    kwargs = dict(dynamics="analytic", episode_seconds=0.05, reset_noise_scale=0.3)
    batched = FurutaVectorEnv(4, **kwargs)
    sync = gym.vector.SyncVectorEnv([lambda: gym.make(FURUTA_ID, **kwargs)] * 4)
    return batched, sync, kwargs


def test_batched_env_equals_sync_vector_env_with_autoreset(furuta_pair):
    """Step i of copy k is the single env's, through two truncations and next-step autoresets."""
    batched, sync, _ = furuta_pair
    seed = 11
    out, ref = batched.reset(seed=seed), sync.reset(seed=seed)
    assert _max_diff(out[0], ref[0]) == 0.0 and set(out[1]) == set(ref[1])
    rng = np.random.default_rng(0)
    saw_reset_step = 0
    for i in range(60):
        actions = rng.uniform(-8.0, 8.0, size=(4, 1))  # beyond ±5 V: clipping is compared too
        out, ref = batched.step(actions), sync.step(actions)
        _assert_same_step(out, ref)
        if i in (25, 51):  # the step after a truncation is a reset: Gymnasium's NEXT_STEP mode
            saw_reset_step += 1
            np.testing.assert_array_equal(out[1], 0.0)
            assert not out[2].any() and not out[3].any() and np.all(out[4]["time"] == 0.0)
        assert out[3].all() == (i in (24, 50))
    assert saw_reset_step == 2
    assert batched.metadata["autoreset_mode"] == sync.metadata["autoreset_mode"]


def test_same_step_autoreset_equals_sync_vector_env():
    """autoreset_mode=SAME_STEP: the ending step returns the reset observation, with the last one
    and its info in final_obs/final_info, exactly as Gymnasium's SyncVectorEnv in that mode."""
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    from furuta_gym.envs.vector import FurutaVectorEnv

    kwargs = dict(dynamics="analytic", episode_seconds=0.02, reset_noise_scale=0.3)
    mode = AutoresetMode.SAME_STEP
    batched = FurutaVectorEnv(3, autoreset_mode=mode, **kwargs)
    sync = gym.vector.SyncVectorEnv([lambda: gym.make(FURUTA_ID, **kwargs)] * 3, autoreset_mode=mode)
    batched.reset(seed=4), sync.reset(seed=4)
    rng = np.random.default_rng(5)
    finals = 0
    for i in range(23):
        actions = rng.uniform(-5.0, 5.0, size=(3, 1))
        out, ref = batched.step(actions), sync.step(actions)
        info, info_r = dict(out[4]), dict(ref[4])
        assert ("final_obs" in info) == ("final_obs" in info_r) == (i % 10 == 9)
        if "final_obs" in info_r:
            finals += 1
            final_obs, final_obs_r = info.pop("final_obs"), info_r.pop("final_obs")
            assert max(_max_diff(final_obs[k], final_obs_r[k]) for k in range(3)) <= 1e-12
            np.testing.assert_array_equal(info.pop("_final_obs"), info_r.pop("_final_obs"))
            final, final_r = info.pop("final_info"), info_r.pop("final_info")
            assert set(final) == set(final_r)
            for key in final_r:
                assert _max_diff(final[key], final_r[key]) <= 1e-12, key
            np.testing.assert_allclose(final["time"], 0.02)
            assert np.all(info["time"] == 0.0)
        _assert_same_step((*out[:4], info), (*ref[:4], info_r))
    assert finals == 2

    # DISABLED: an ended copy must be reset by the user before it steps again
    manual = FurutaVectorEnv(3, autoreset_mode="Disabled", **kwargs)
    manual.reset(seed=0)
    for _ in range(10):
        *_, truncated, _ = manual.step(np.zeros((3, 1)))
    assert truncated.all()
    with pytest.raises(ValueError, match="reset_mask"):
        manual.step(np.zeros((3, 1)))
    manual.reset(options={"reset_mask": np.ones(3, dtype=bool)})
    assert not manual.step(np.zeros((3, 1)))[3].any()


def test_copy_k_is_the_single_env_reset_with_seed_plus_k(furuta_pair):
    import gymnasium as gym

    batched, _, kwargs = furuta_pair
    batched.reset(seed=100)
    single = gym.make(FURUTA_ID, **kwargs)
    obs_k, _ = single.reset(seed=102)
    rng = np.random.default_rng(1)
    states = []
    for _ in range(20):
        actions = rng.uniform(-5.0, 5.0, size=(4, 1))
        obs, *_ = batched.step(actions)
        obs_k, *_ = single.step(actions[2])
        states.append((obs[2], obs_k))
    assert max(_max_diff(a, b) for a, b in states) <= 1e-12
    assert _max_diff(states[0][0], states[-1][0]) > 1e-3  # it moved


def test_partial_reset_and_state_option(furuta_pair):
    batched, _, _ = furuta_pair
    x = np.array([0.1, 3.0, 0.0, 0.0])
    obs, info = batched.reset(options={"state": x})
    np.testing.assert_array_equal(obs, np.tile(x, (4, 1)))
    batched.step(np.ones((4, 1)))
    mask = np.array([False, True, False, False])
    obs, info = batched.reset(seed=5, options={"reset_mask": mask})
    assert np.any(obs[1] != x) and np.all(obs[[0, 2, 3]] != x)  # copy 1 re-drawn, others moved on
    np.testing.assert_array_equal(info["_time"], mask)
    with pytest.raises(ValueError, match="shape"):
        batched.reset(options={"state": np.zeros(3)})


def test_rollout_method_equals_stepping_the_env():
    """A jittable policy run inside lax.scan gives the env's own trajectory, encoder model included."""
    from furuta_gym.envs.vector import FurutaVectorEnv

    env = FurutaVectorEnv(3, dynamics="analytic", encoder_counts=2048, reset_noise_scale=0.5)
    obs, _ = env.reset(seed=3)
    out = jax.tree_util.tree_map(np.asarray, env.rollout(lqr_like, 40))
    seen = []
    for t in range(40):
        seen.append(obs)
        obs, reward, term, trunc, info = env.step(out.actions[:, t])
        assert _max_diff(info["state"], out.states[:, t + 1]) <= 1e-12
        assert _max_diff(reward, out.rewards[:, t]) <= 1e-12
        assert not term.any() and not trunc.any()
    # the policy acted on the env's observations, clipped to the limit
    policy_u = jax.vmap(jax.vmap(lqr_like))(jnp.asarray(np.stack(seen, axis=1)))
    np.testing.assert_allclose(out.actions, np.clip(policy_u, -5.0, 5.0), rtol=0, atol=1e-12)
    # observations were quantised to the 2048-count encoder, states were not
    step = 2 * np.pi / 2048
    np.testing.assert_allclose(obs[:, :2] / step, np.round(obs[:, :2] / step), atol=1e-9)
    assert _max_diff(obs[:, :2], info["state"][:, :2]) > 0


def test_broken_model_diverges_in_one_copy_only():
    """A blown-up model ends copy 1's episode (diverged, last good obs, no NaN); copies 0 and 2
    equal single envs of the same model, and copy 1 is autoreset at the next step."""
    import gymnasium as gym

    from furuta_gym.envs.vector import NMSDVectorEnv

    # a "fitted" N-MSD whose cubic spring came out softening: beyond |p| ≈ 0.45 m it explodes
    broken = NMSD(params=NMSDParameters(k2=-50.0))
    starts = np.array([[0.0, 0.0], [2.0, 0.0], [0.1, 0.0]])
    batched = NMSDVectorEnv(3, dynamics=broken, reset_noise_scale=0.0)
    sync = gym.vector.SyncVectorEnv([lambda: gym.make(NMSD_ID, dynamics=broken, reset_noise_scale=0.0)] * 3)
    out, ref = batched.reset(options={"state": starts}), sync.reset(options={"state": starts[0]})
    for k in (1, 2):  # SyncVectorEnv passes one options dict to all; start copies 1, 2 by hand
        sync.envs[k].reset(options={"state": starts[k]})
        sync._env_obs[k] = starts[k]
    div_step = None
    for i in range(40):
        actions = np.full((3, 1), 0.1)
        out, ref = batched.step(actions), sync.step(actions)
        assert np.all(np.isfinite(out[0])) and np.all(np.isfinite(out[1]))
        # the exploding copy amplifies round-off (1e-12 relative per step); the others are exact
        _assert_same_step(out, ref, rtol=1e-8)
        assert _max_diff(out[0][[0, 2]], ref[0][[0, 2]]) <= 1e-12
        if out[4]["diverged"][1]:
            div_step = i
            assert out[2][1] and not out[2][[0, 2]].any()
            assert abs(out[0][1, 0]) > 2.0  # the last good observation, not the start
        if div_step is not None and i == div_step + 1:
            np.testing.assert_array_equal(out[0][1], [0.0, 0.0])  # autoreset (no noise)
    assert div_step is not None and not out[4]["diverged"][[0, 2]].any()


def test_learned_checkpoint_by_path_matches_single_envs(tmp_path):
    """dynamics=<checkpoint path>: a (untrained) DeLaN saved by furuta_gym.training loads in the
    batched env and steps exactly like single envs loading the same file."""
    import gymnasium as gym

    from furuta_gym.envs.vector import FurutaVectorEnv
    from furuta_gym.models import make_model
    from furuta_gym.training.checkpoint import save_model

    path = save_model(tmp_path / "dln.eqx", make_model("furuta", "dln", key=jax.random.PRNGKey(3)))
    batched = FurutaVectorEnv(2, dynamics=str(path))
    sync = gym.vector.SyncVectorEnv([lambda: gym.make(FURUTA_ID, dynamics=str(path))] * 2)
    out, ref = batched.reset(seed=7), sync.reset(seed=7)
    np.testing.assert_array_equal(out[0], ref[0])
    rng = np.random.default_rng(2)
    for _ in range(10):
        actions = rng.uniform(-5.0, 5.0, size=(2, 1))
        out, ref = batched.step(actions), sync.step(actions)
        _assert_same_step(out, ref)
    assert _max_diff(out[4]["state"], 0.0) > 1e-3 and not out[4]["diverged"].any()


def test_make_vec_modes():
    """make_vec: the vector entry point gives the batched env for a model backend from
    BATCHED_FROM copies on (or when asked), a SyncVectorEnv below that and for MuJoCo;
    vectorization_mode="sync" works for the MuJoCo ground truth."""
    import gymnasium as gym

    from furuta_gym.envs.vector import BATCHED_FROM, FurutaVectorEnv, NMSDVectorEnv

    sync = gym.make_vec(FURUTA_ID, num_envs=2, vectorization_mode="sync")
    obs, _ = sync.reset(seed=0)
    obs2, rew, term, trunc, info = sync.step(np.full((2, 1), 1.0))
    assert obs2.shape == (2, 4) and np.all(np.isfinite(obs2)) and np.any(obs2 != obs)
    sync.close()

    # the registered vector_entry_point: batched JAX for a model, Gymnasium's sync env for MuJoCo
    env = gym.make_vec(FURUTA_ID, num_envs=BATCHED_FROM, dynamics="analytic")
    assert isinstance(env.unwrapped, FurutaVectorEnv) and env.num_envs == BATCHED_FROM
    small = gym.make_vec(FURUTA_ID, num_envs=BATCHED_FROM - 1, dynamics="analytic")
    assert isinstance(small, gym.vector.SyncVectorEnv)  # N kernel calls beat one XLA step here
    # the same numbers either way: copy k is the single env reset with seed + k
    big = gym.make_vec(FURUTA_ID, num_envs=BATCHED_FROM - 1, dynamics="analytic", batched=True)
    assert isinstance(big.unwrapped, FurutaVectorEnv)
    np.testing.assert_allclose(small.reset(seed=4)[0], big.reset(seed=4)[0], rtol=0, atol=0)
    actions = np.linspace(-5.0, 5.0, BATCHED_FROM - 1)[:, None]
    for _ in range(5):
        a, b = small.step(actions)[0], big.step(actions)[0]
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    assert np.abs(a - small.reset(seed=4)[0]).max() > 1e-3
    small.close(), big.close()
    with pytest.raises(ValueError, match="batched must be"):
        gym.make_vec(FURUTA_ID, num_envs=2, dynamics="analytic", batched="yes")
    env = gym.make_vec(
        NMSD_ID,
        num_envs=2,
        vectorization_mode="vector_entry_point",
        dynamics="analytic",
        batched=True,
    )
    assert isinstance(env.unwrapped, NMSDVectorEnv)
    obs, info = env.reset(seed=0, options={"target": -0.2})
    np.testing.assert_array_equal(info["target"], [-0.2, -0.2])
    default = gym.make_vec(FURUTA_ID, num_envs=2)  # dynamics="mujoco"
    assert isinstance(default, gym.vector.SyncVectorEnv)
    default.close()


def test_bad_input_is_one_clear_error():
    from furuta_gym.envs.vector import FurutaVectorEnv

    with pytest.raises(ValueError, match="vectorization_mode='sync'"):
        FurutaVectorEnv(2, dynamics="mujoco")
    with pytest.raises(ValueError, match="measurement_noise"):
        FurutaVectorEnv(2, measurement_noise=0.01)
    with pytest.raises(ValueError, match="num_envs"):
        FurutaVectorEnv(0)
    env = FurutaVectorEnv(2, dynamics="analytic")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([[0.0], [np.nan]]))
    with pytest.raises(ValueError, match=r"shape \(2, 1\)"):
        env.step(np.zeros((3, 1)))


def _run_env(env, seed, actions, **reset_options):
    outs = [env.reset(seed=seed, options=reset_options or None)[0]]
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        outs.append((obs, reward, terminated, truncated, info["energy"], info["state"], info["time"]))
    return outs


def test_split_and_worker_processes_give_every_copy_the_same_numbers():
    """chunks= (threads in this process) and workers= (processes) only change where copies are
    computed: a learned model's copies match the unsplit env through truncations and autoresets,
    a task change reaches the workers, and close() stops them and refuses further steps."""
    import gymnasium as gym

    from furuta_gym.envs.vector import FurutaVectorEnv, NMSDVectorEnv
    from furuta_gym.models import make_model

    model = make_model("furuta", "dln", jax.random.PRNGKey(3))
    kwargs = dict(dynamics=model, episode_seconds=0.02, reset_noise_scale=0.3)
    actions = np.random.default_rng(2).uniform(-6.0, 6.0, size=(25, 10, 1))
    with FurutaVectorEnv(10, chunks=1, **kwargs) as whole:
        reference = _run_env(whole, 7, actions)
    assert sum(o[3].sum() for o in reference[1:]) == 20  # two truncations of every copy
    for split in (dict(chunks=3), dict(workers=2)):
        with FurutaVectorEnv(10, **split, **kwargs) as env:
            assert (env.chunks, env.workers) == ((3, 0) if "chunks" in split else (1, 2))
            outs = _run_env(env, 7, actions)
        assert _max_diff(outs[0], reference[0]) == 0.0
        for got, want in zip(outs[1:], reference[1:], strict=True):
            for a, b in zip(got, want, strict=True):
                assert _max_diff(a, b) <= 1e-12, split

    targets = []
    for workers in (0, 2):
        env = gym.make_vec("furuta_gym/NMSD-v0", num_envs=6, dynamics="analytic", workers=workers)
        assert isinstance(env, NMSDVectorEnv) and env.workers == workers
        env.reset(seed=1, options={"target": 0.4})
        _, reward, *_, info = env.step(np.full((6, 1), 2.0))
        targets.append((reward, info["target"]))
        if workers:
            processes = env._workers._processes
            env.close()
            assert all(p.wait(timeout=10) == 0 for p in processes)
            with pytest.raises(RuntimeError, match="closed"):
                env._workers.step(np.zeros((6, 2)), np.zeros((6, 1)))
    np.testing.assert_array_equal(targets[0][1], 0.4)
    assert _max_diff(targets[0][0], targets[1][0]) <= 1e-12 and _max_diff(targets[0][1], targets[1][1]) == 0.0


def test_auto_chunks_and_bad_split_arguments():
    import gymnasium as gym

    from furuta_gym.envs.vector import FurutaVectorEnv, auto_chunks

    assert [auto_chunks(n, cores=2) for n in (1, 511, 1024, 4096, 8191, 8192, 16384)] == [1, 1, 2, 4, 4, 1, 1]
    assert auto_chunks(4096, cores=8) == 8
    with pytest.raises(ValueError, match="chunks must be an integer from 1 to num_envs = 4"):
        FurutaVectorEnv(4, dynamics="analytic", chunks=5)
    with pytest.raises(ValueError, match="workers must be an integer from 0"):
        FurutaVectorEnv(4, dynamics="analytic", workers=-1)
    with pytest.raises(ValueError, match="pass one of the two"):
        FurutaVectorEnv(4, dynamics="analytic", workers=2, chunks=2)
    with pytest.raises(ValueError, match="SyncVectorEnv of single envs .* takes neither"):
        gym.make_vec(FURUTA_ID, num_envs=2, dynamics="mujoco", workers=2)


def test_worker_that_cannot_rebuild_the_model_is_one_clear_error(monkeypatch):
    """A model class the worker interpreter cannot import ends the constructor with the reason,
    not a hang; a model importable on the env's path works (this module's BlowUp)."""
    from furuta_gym.envs.vector import NMSDVectorEnv

    with NMSDVectorEnv(3, dynamics=BlowUp(), workers=1) as env:  # importable: tests/ is on sys.path
        env.reset(options={"state": np.zeros(2)})
        assert env.step(np.zeros((3, 1)))[0].shape == (3, 2)
    # as if defined in the user's script: it pickles here, but a worker's __main__ is not that script
    monkeypatch.setattr(BlowUp, "__module__", "__main__")
    monkeypatch.setattr(sys.modules["__main__"], "BlowUp", BlowUp, raising=False)
    with pytest.raises(RuntimeError, match=r"worker 0: .*class must be importable by name"):
        NMSDVectorEnv(3, dynamics=BlowUp(), workers=1)

    class Local(BlowUp):  # defined in a function: does not pickle at all
        pass

    with pytest.raises(ValueError, match="workers=1: the model or task cannot be sent"):
        NMSDVectorEnv(3, dynamics=Local(), workers=1)


def test_rollout_in_concurrent_chunks_equals_one_batch_and_still_traces():
    """chunks= only changes where the copies run; inside jit the rollout is one batch."""
    x0s = np.random.default_rng(4).uniform(-0.3, 0.3, size=(7, 4))
    x0s[:, 1] += np.pi
    kwargs = dict(dt=DT, action_limit=5.0)
    whole = rollout(Furuta(), lqr_like, x0s, 50, chunks=1, **kwargs)
    split = rollout(Furuta(), lqr_like, x0s, 50, chunks=3, **kwargs)
    for a, b in zip(split, whole, strict=True):
        assert a.shape == b.shape and _max_diff(a, b) <= 1e-12
    assert _max_diff(whole.states[:, -1], whole.states[:, 0]) > 1e-3  # it moved
    traced = jax.jit(lambda x: rollout(Furuta(), lqr_like, x, 50, chunks=3, **kwargs).states)(x0s)
    assert _max_diff(traced, whole.states) <= 1e-12
    with pytest.raises(ValueError, match=r"chunks must be an integer from 1 to the number of copies \(7\)"):
        rollout(Furuta(), lqr_like, x0s, 5, chunks=8, **kwargs)


def test_an_env_refused_at_construction_closes_quietly():
    # VectorEnv.__del__ calls close() on an env whose __init__ raised before its parts existed
    import gc
    import warnings

    from furuta_gym.envs.vector import FurutaVectorEnv

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="workers must be an integer"):
            FurutaVectorEnv(2, workers=5)
        env = object.__new__(FurutaVectorEnv)
        env.close()  # nothing was built: nothing to close, no AttributeError
        gc.collect()


def test_the_batched_env_steps_the_analytic_furuta_with_its_trig_shared():
    """The batched step integrates the analytic Furuta (also under a plant's effects) as
    FurutaSharedTrig: one sin β per RK4 stage where Furuta's own graph has XLA:CPU evaluate it in
    several kernels (about twice the steps/s, BENCHMARKS.md). The user's model stays Furuta; the
    parity tests above check the numbers against Furuta's own step. Other models are left alone."""
    from furuta_gym.effects import WithEffects
    from furuta_gym.envs._jax_rollout import stepping_model
    from furuta_gym.envs.vector import FurutaVectorEnv
    from furuta_gym.models import FurutaSharedTrig

    env = FurutaVectorEnv(8, dynamics="analytic")
    assert type(env.system) is Furuta
    xs, us = np.zeros((8, 4)), np.zeros((8, 1))
    text = env._step_fn.lower(*env._step_args, xs, us).compile().as_text()
    if jax.default_backend() == "cpu":
        assert text.count(" sine(") <= 4 * env.frame_skip + 2
    plant = WithEffects(Furuta(), ())
    assert type(stepping_model(plant).base) is FurutaSharedTrig and type(plant.base) is Furuta
    assert stepping_model(NMSD()) == NMSD()
