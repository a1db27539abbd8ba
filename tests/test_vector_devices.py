"""``make_vec(..., devices=...)``: the batched env's copies split over JAX devices give every copy
the numbers of the unsplit env. Two host devices need XLA_FLAGS before JAX starts, so that part
runs in a fresh interpreter."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

# A learned model (so the step is a real network), episodes short enough that every copy
# truncates and autoresets twice.
SCRIPT = textwrap.dedent("""
    import json
    import gymnasium as gym
    import jax
    import numpy as np
    import furuta_gym
    from furuta_gym.envs import Episode
    from furuta_gym.models import make_model

    furuta_gym.enable_x64()
    model = make_model("furuta", "dln", jax.random.PRNGKey(3))
    actions = np.random.default_rng(2).uniform(-6.0, 6.0, size=(25, 8, 1))

    def run(num_envs, seed, actions, **split):
        env = gym.make_vec("furuta_gym/Furuta-v0", num_envs=num_envs, dynamics=model, batched=True,
                           episode=Episode(seconds=0.02, reset_noise_scale=0.3), **split)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for a in actions:
            obs, reward, terminated, truncated, info = env.step(a)
            out += [obs, reward, terminated, truncated, info["state"], info["energy"]]
        assert (env.unwrapped.devices is None) == (not split)
        env.close()
        return [np.asarray(o, dtype=float).tolist() for o in out]

    print(json.dumps({
        "n_devices": len(jax.devices()),
        # 7 copies: the split pads to 8
        "one": run(7, 7, actions[:, :7]), "two": run(7, 7, actions[:, :7], devices=2),
        # 8 copies in halves of 4: each device against one device running the same 4 copies
        # (copy k is seeded seed + k, so copies 4-7 of seed 7 are copies 0-3 of seed 11)
        "halves": run(8, 7, actions, devices=jax.devices()[::-1]),
        "first": run(4, 7, actions[:, :4]), "second": run(4, 11, actions[:, 4:]),
    }))
""")


def test_two_host_devices_give_every_copy_the_one_device_numbers():
    env = {
        **os.environ,
        "XLA_FLAGS": "--xla_force_host_platform_device_count=2 --xla_cpu_multi_thread_eigen=false",
    }
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["n_devices"] == 2
    # each device computes exactly what one device computes for the same copies
    for got, first, second in zip(result["halves"], result["first"], result["second"], strict=True):
        np.testing.assert_array_equal(np.asarray(got), np.concatenate([first, second]))
    # against one device stepping all 7 at once, only XLA's kernels for another batch shape
    # differ: in the last bit, as with chunks= (tests/test_vector.py)
    for got, want in zip(result["two"], result["one"], strict=True):
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(result["two"][0], result["one"][0])  # the reset: no arithmetic


def test_devices_arguments_are_checked():
    import jax

    from furuta_gym.envs.vector import FurutaVectorEnv

    with FurutaVectorEnv(3, devices=1) as env:
        assert env.devices == tuple(jax.devices()[:1]) and env.chunks == 1
        obs, _ = env.reset(seed=0)
        with FurutaVectorEnv(3) as plain:
            np.testing.assert_array_equal(
                env.step(np.ones((3, 1)))[0], (plain.reset(seed=0), plain.step(np.ones((3, 1))))[1][0]
            )
    too_many = len(jax.devices()) + 1
    with pytest.raises(ValueError, match="xla_force_host_platform_device_count"):
        FurutaVectorEnv(3, devices=too_many)
    with pytest.raises(ValueError, match="pass one of them"):
        FurutaVectorEnv(3, devices=1, chunks=1)
    with pytest.raises(ValueError, match="distinct JAX devices"):
        FurutaVectorEnv(3, devices=["cpu:0"])
    import gymnasium as gym

    # devices=None is the default: it does not force the batched env on make_vec, devices=1 does
    assert isinstance(
        gym.make_vec("furuta_gym/Furuta-v0", num_envs=3, dynamics="analytic", devices=None), gym.vector.SyncVectorEnv
    )
    assert isinstance(gym.make_vec("furuta_gym/Furuta-v0", num_envs=3, dynamics="analytic", devices=1), FurutaVectorEnv)
