"""studies/rl_from_learned_models.py: its randomised learned-model env, its docs table and
bench/rl_wall_time.py's BENCHMARKS.md section."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "studies"
CHECKPOINT = ROOT / "results" / "reproduce" / "runs" / "furuta" / "dln_prop" / "seed0" / "model.eqx"


def test_rl_learned_docs_table_matches_its_results():
    if not any((ROOT / "results" / "rl_learned").glob("*_seed0.json")):
        pytest.skip("results/rl_learned not generated")
    proc = subprocess.run(
        [sys.executable, str(EXPERIMENTS / "rl_from_learned_models_table.py"), "--check"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_a_learned_model_randomised_env_draws_its_scale_at_each_reset():
    """Each reset draws the learned model's scale within ±spread, and the step's plant uses it."""
    pytest.importorskip("gymnax")
    if not CHECKPOINT.is_file():
        pytest.skip("the reproduction's DeLaN L_prop checkpoint is not here")
    import jax

    sys.path.insert(0, str(EXPERIMENTS))
    try:
        import rl_from_learned_models as experiment
    finally:
        sys.path.remove(str(EXPERIMENTS))
    env, params = experiment.training_env("dln_prop", randomize=True)
    nominal = float(env.plant(params).scale)
    scales = np.array([float(env.reset(jax.random.PRNGKey(k), params)[1].physical) for k in range(8)])
    assert np.all(np.abs(scales / nominal - 1.0) <= experiment.SPREAD) and np.ptp(scales) > 0
    _, state = env.reset(jax.random.PRNGKey(0), params)
    assert float(env.plant(params, state).scale) == scales[0]
    assert env.plant(params, env.state_at(np.zeros(4), params)).scale == nominal  # deployment-style start


def test_rl_wall_time_benchmark_section_matches_its_results():
    if "<!-- bench/rl_wall_time.py:start -->" not in (ROOT / "BENCHMARKS.md").read_text():
        pytest.skip("BENCHMARKS.md has no wall-time-to-swing-up section yet")
    proc = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "rl_wall_time.py"), "--check"],
        capture_output=True,
        text=True,
        cwd=ROOT / "bench",
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def _equal_budget_runs():
    folder = ROOT / "results" / "rl_equal_budget"
    paths = [folder / f"{algo}_seed0.json" for algo in ("sac", "ppo")]
    if not all(p.is_file() for p in paths):
        pytest.skip("results/rl_equal_budget not generated")
    import json

    return [{int(b): row for b, row in json.loads(p.read_text())["budgets"].items()} for p in paths]


def test_docs_statements_on_sac_and_ppo_at_equal_budgets_hold_in_the_results():
    """docs/rl.md: SAC succeeds from ≥ 90 % of the starts at a budget where PPO succeeds from none;
    PPO needs ≥ 10× the env steps but less wall time to its first such policy; SAC is not run at
    PPO's largest budget."""
    sac, ppo = _equal_budget_runs()

    def success(row):
        return row["mujoco"]["nominal"]["seeded_success"]

    assert any(success(sac[b]) >= 0.9 and success(ppo[b]) == 0.0 for b in set(sac) & set(ppo))
    sac_first = min(b for b in sac if success(sac[b]) >= 0.9)
    ppo_first = min(b for b in ppo if success(ppo[b]) >= 0.9)
    assert ppo_first >= 10 * sac_first
    assert ppo[ppo_first]["train_seconds"] < sac[sac_first]["train_seconds"]
    assert max(ppo) > max(sac)


def test_docs_statements_on_policies_trained_in_learned_models_hold_in_the_results():
    """docs/rl.md "Reading it": every L_prop policy succeeds from x0 = 0 and every start on the
    nominal and `coulomb` plants; the DeLaN L_traj policies from none; each baseline's worst plant
    is worse than any L_prop policy's worst, and its own-model return below every L_prop one."""
    import json

    rows = {p.stem: json.loads(p.read_text()) for p in (ROOT / "results" / "rl_learned").glob("*_seed0.json")}
    if not rows:
        pytest.skip("results/rl_learned not generated")
    prop = [r for k, r in rows.items() if k.split("_")[1] == "prop"]
    baselines = [r for k, r in rows.items() if k.startswith(("dln_traj", "adln_aph"))]
    assert len(prop) == 4 and len(baselines) == 4
    plants = ("nominal", "cable_spring", "coulomb")
    for r in prop:
        for plant in ("nominal", "coulomb"):
            assert r["mujoco"][plant]["x0"]["success"] and r["mujoco"][plant]["seeded_success"] == 1.0
    for r in (r for k, r in rows.items() if k.startswith("dln_traj")):
        assert all(r["mujoco"][p]["seeded_success"] == 0.0 and not r["mujoco"][p]["x0"]["success"] for p in plants)

    def worst(r):
        return min(r["mujoco"][p]["seeded_success"] for p in plants)

    assert max(map(worst, baselines)) < min(map(worst, prop))
    assert max(r["model_return"] for r in baselines) < min(r["model_return"] for r in prop)
