"""furuta_gym.inline_cpu_dispatch: an explicit, checked opt-in, never implicit."""

import subprocess
import sys
import textwrap


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=300)


def test_inline_dispatch_is_opt_in_and_refused_once_jax_has_started():
    out = _run("""
        import jax
        import furuta_gym                       # importing changes nothing
        assert jax.config.read("jax_cpu_enable_async_dispatch")
        furuta_gym.inline_cpu_dispatch()
        assert not jax.config.read("jax_cpu_enable_async_dispatch")
        import jax.numpy as jnp
        assert float(jnp.ones(3).sum()) == 3.0
        furuta_gym.inline_cpu_dispatch()        # already on: nothing to do
        print("ok")
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
    late = _run("""
        import jax.numpy as jnp
        import furuta_gym
        jnp.ones(2) + 1
        try:
            furuta_gym.inline_cpu_dispatch()
        except RuntimeError as exc:
            print("refused:", exc)
    """)
    assert late.returncode == 0, late.stderr
    assert "refused: inline_cpu_dispatch() must be called before the first JAX computation" in late.stdout
