"""``reproduce --executor ray``: on a local Ray instance with two workers, a tiny reproduction
gives the local pool's tables, a second call reuses the finished runs, and a worker killed in
the middle of training is retried and resumes from its last epoch instead of starting over.
``studies/select_option.py --executor ray`` makes the local pool's choice from the same runs.
Skipped when Ray (the ``[cluster]`` extra) is not installed."""

import dataclasses
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ray = pytest.importorskip("ray")

from furuta_gym.training import checkpoint as ckpt  # noqa: E402
from furuta_gym.training.reproduce import ReproduceSettings, reproduce  # noqa: E402

# Only L_Iτ epochs (no trajectory stage to compile), enough of them that a worker can be killed
# while it trains (they run in compiled blocks of about two seconds after a first short one);
# two seeds, so both workers train at once.
EPOCHS = 400
CONFIG = ReproduceSettings(
    quick=True,
    systems=("nmsd",),
    pairs=(("dln", "prop"),),
    prop_epochs={"nmsd": (EPOCHS, 0, 0)},
    seeds=(0, 1),
    jobs=2,
    progress=False,
    figures=False,
    ground_truth="analytic",
)
RUN = Path("runs") / "nmsd" / "dln_prop"


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A shared compilation cache (the local pool's workers compile, Ray's reuse it: same
    executables, and the tests take seconds instead of minutes), the same single-thread XLA
    flags for both kinds of worker, and a 2-CPU Ray instance; yields the module's folder."""
    root = tmp_path_factory.mktemp("cluster")
    env = {
        "JAX_COMPILATION_CACHE_DIR": str(root / "jax"),
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
        "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false",
    }
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        ray.init(num_cpus=2, include_dashboard=False, object_store_memory=100 * 2**20)
        yield root
    finally:
        if ray.is_initialized():
            ray.shutdown()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@pytest.fixture(scope="module")
def workspace(cluster):
    """The module's folder with the local pool's reference run of CONFIG (``local/``)."""
    reproduce(cluster / "local", CONFIG, log=lambda msg: None)
    return cluster


def _metrics(out: Path, seed: int) -> dict:
    metrics = json.loads((out / RUN / f"seed{seed}" / "metrics.json").read_text())
    metrics.pop("_seconds")
    return metrics


def _statuses(paths) -> list[str]:
    seconds = json.loads(paths["run.json"].read_text())["seconds"]
    return [seconds[f"nmsd/dln_prop/seed{k}"]["status"] for k in CONFIG.seeds]


def test_ray_run_gives_the_local_tables_and_reuses_finished_runs(workspace):
    out = workspace / "ray"
    ray_config = dataclasses.replace(CONFIG, executor="ray", figures=True)
    paths = reproduce(out, ray_config, log=lambda msg: None)
    assert _statuses(paths) == ["trained", "trained"]
    assert paths["tables.csv"].read_text() == (workspace / "local" / "tables.csv").read_text()
    for seed in CONFIG.seeds:
        assert _metrics(out, seed) == _metrics(workspace / "local", seed)
    # the figures task ran on a worker too, into the same folder layout
    assert paths["predictions_nmsd"] == out.resolve() / "figures" / paths["predictions_nmsd"].name
    again = reproduce(out, ray_config, log=lambda msg: None)
    assert _statuses(again) == ["reused", "reused"]


def _worker_pid(task_name: str) -> int | None:
    """The process of the Ray worker running ``task_name`` (its process title is ray::<name>)."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            title = (entry / "cmdline").read_bytes().split(b"\0")[0].decode().strip()
        except OSError:
            continue
        if title == f"ray::{task_name}":
            return int(entry.name)
    return None


def _saved_epoch(state: Path) -> int:
    try:
        return int(ckpt.read_header(state)["state"]["epoch"])
    except (OSError, ValueError, KeyError):  # not written yet, or being replaced
        return 0


def _kill_mid_run(history: Path, task_name: str, after_epochs: int, timeout: float = 300.0) -> list[str]:
    """SIGKILL the worker training ``task_name`` once its history holds ``after_epochs`` epochs,
    all of them in its saved state too; returns those history lines."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        lines = history.read_text().splitlines() if history.exists() else []
        if len(lines) >= after_epochs and _saved_epoch(history.parent / "train_state.eqx") >= len(lines):
            pid = _worker_pid(task_name)
            assert pid is not None, f"no worker runs {task_name}"
            os.kill(pid, signal.SIGKILL)
            return lines
        time.sleep(0.02)
    raise AssertionError(f"{history} never reached {after_epochs} epochs")


def test_a_killed_worker_is_retried_and_resumes_its_training(workspace):
    out = workspace / "killed"
    ray_config = dataclasses.replace(CONFIG, executor="ray")
    done = {}
    runner = threading.Thread(target=lambda: done.update(paths=reproduce(out, ray_config, log=lambda m: None)))
    runner.start()
    try:
        before = _kill_mid_run(out / RUN / "seed0" / "history.jsonl", "nmsd/dln_prop/seed0", after_epochs=5)
    finally:
        runner.join(timeout=600)
    assert 5 <= len(before) < EPOCHS
    assert _statuses(done["paths"]) == ["resumed", "trained"]
    lines = (out / RUN / "seed0" / "history.jsonl").read_text().splitlines()
    # the epochs saved before the kill were kept as written (each line carries its own timing: a
    # restart would have rewritten them), and training went on from there, each epoch once
    assert lines[: len(before)] == before
    assert [json.loads(line)["epoch"] for line in lines] == list(range(1, EPOCHS + 1))
    # and the resumed model is the one an uninterrupted run trains
    assert _metrics(out, 0) == _metrics(workspace / "local", 0)


STUDIES = Path(__file__).resolve().parents[1] / "studies"
# The smallest selection the script runs: candidates trained as `reproduce --quick` trains, the
# N-MSD DeLaN's L_Iτ stage alone, two lengths of it to choose between, two model seeds (so the
# seed-by-seed rule and its table columns are compared too).
SELECTION = ("--system", "nmsd", "--kinds", "dln", "--quick", "--train", "epochs", "[20,0,0]", "[40,0,0]")
SELECTION += ("--seeds", "2")


def _select(out: Path, *extra: str, env=None) -> dict:
    """Run studies/select_option.py as a user does; its JSON record without the training seconds
    (how long a run took depends on what trained beside it)."""
    command = [sys.executable, str(STUDIES / "select_option.py"), *SELECTION, "--out", str(out), *extra]
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr[-4000:]
    record = json.loads((out / "nmsd.json").read_text())
    for scores in record["scores"].values():
        for score in scores.values():
            score.pop("train_seconds")
    return record


def _files(out: Path) -> set[Path]:
    return {p.relative_to(out) for p in out.rglob("*") if p.is_file()}


def test_select_option_on_ray_makes_the_local_pools_choice_from_the_same_runs(cluster, tmp_path):
    # the local pool first, with Ray hidden from its whole process tree: it needs no [cluster] extra
    hidden = tmp_path / "hidden"
    (hidden / "ray").mkdir(parents=True)
    (hidden / "ray" / "__init__.py").write_text("raise ImportError('Ray is hidden from this process')\n")
    no_ray = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(hidden), os.environ.get("PYTHONPATH")])))
    local = _select(cluster / "select_local", env=no_ray)
    # each candidate × seed a task on the module's Ray instance, which the script joins
    address = ray.get_runtime_context().gcs_address
    on_ray = _select(cluster / "select_ray", "--executor", "ray", "--address", address)
    assert on_ray == local  # the same scores, seed by seed, the same decision
    # both values were trained on both seeds: four tasks, and the seed-by-seed rule decided
    assert [score["seeds"] for score in local["scores"]["dln"].values()] == [[0, 1], [0, 1]]
    assert set(local["chosen"]) == {"dln"} and "vs_first" in local["scores"]["dln"]["[40,0,0]"]
    assert _files(cluster / "select_ray") == _files(cluster / "select_local")
    # Ray's tasks find the runs the local pool trained by their recorded settings and reuse them
    again = _select(cluster / "select_local", "--executor", "ray", "--address", address)
    assert again == local
    for candidate in (cluster / "select_local" / "nmsd_dln").iterdir():
        seconds = json.loads((candidate / "run.json").read_text())["seconds"]
        assert [v["status"] for k, v in seconds.items() if k.startswith("nmsd/dln_prop/")] == ["reused"]
