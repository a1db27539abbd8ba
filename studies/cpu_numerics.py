"""Does a training give the same bits on every x86-64 machine? (issue 68)

Other machines are emulated on this one: the instruction set XLA may use by capping it
(``XLA_FLAGS=--xla_cpu_max_isa=...``), the core count by the process's CPU affinity, the BLAS
kernels OpenBLAS picks by ``OPENBLAS_CORETYPE`` (``Haswell``: an AVX2 machine's; ``SkylakeX``: an
Intel AVX-512 machine's; unset: what OpenBLAS detects here), and NumPy's loops by
``NPY_DISABLE_CPU_FEATURES`` (an AVX2 machine has none of its AVX-512 ones). Each setting runs the same CI-size
training in a fresh process — MuJoCo data as the demo makes it, a DeLaN trained with L_prop
(L_Iτ + λ·L_traj), the scale fit — with furuta_gym's pinned numerics (the default) and without them
(``FURUTA_GYM_NATIVE_ISA=1``), and records a digest of the trained parameters and their largest
relative difference from the reference (the first setting). Writes ``results/cpu_numerics/`` and
the ``cpu-numerics`` block of docs/conventions.md.

    python studies/cpu_numerics.py             # run every setting (≈ 4 min on 2 cores), write both
    python studies/cpu_numerics.py --check     # exit 1 if the docs block is stale
    python studies/cpu_numerics.py --render    # rewrite the docs block from the committed results
    python studies/cpu_numerics.py --reproduce-quick   # reproduce --quick, pinned, on two machines (≈ 35 min)
    python studies/cpu_numerics.py --demo      # furuta-gym demo (seed 0), pinned, on two machines (≈ 8 min)
    python studies/cpu_numerics.py --one OUT   # (child) one training in this process, saved to OUT
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import fill_block, machine, update  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "cpu_numerics" / "results.json"
DOC = ROOT / "docs" / "conventions.md"
NAME = "cpu-numerics"

# NumPy picks its loops by the CPU too: an AVX2 machine has none of its AVX-512 ones
NO_AVX512_NUMPY = "AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR"
# (label, pinned, XLA cap or None, cores or None for all, OPENBLAS_CORETYPE or None for unset,
# NumPy without its AVX-512 loops)
SETTINGS = [
    ("this machine (AVX-512), 2 cores", True, None, None, None, False),
    ("AVX2 machine, 2 cores", True, "AVX2", None, "Haswell", True),
    ("AVX2 machine, 1 core", True, "AVX2", 1, "Haswell", True),
    ("Intel AVX-512 machine, 1 core", True, None, 1, "SkylakeX", False),
    ("AVX machine (no FMA), 2 cores", True, "AVX", None, "Sandybridge", True),
    ("this machine, user's cap AVX512", True, "AVX512", None, None, False),
    ("this machine (AVX-512), 2 cores", False, None, None, None, False),
    ("AVX2 machine, 2 cores", False, "AVX2", None, "Haswell", True),
    ("this machine (AVX-512), 1 core", False, None, 1, None, False),
    ("Intel AVX-512 machine, 2 cores", False, None, None, "SkylakeX", False),
]


def tiny_training(out: Path) -> None:
    """The CI-size training (the demo's ``--tiny`` data, shorter), its parameters saved to ``out``."""
    import equinox as eqx
    import jax

    from furuta_gym import numerics
    from furuta_gym.training.datagen import FurutaRecipe, generate_datasets
    from furuta_gym.training.train import TrainSettings, train

    recipe = dataclasses.replace(
        FurutaRecipe.small(),
        n_train=4,
        n_test_free=1,
        test_free_duration=1.0,
        n_test_forced=1,
        test_forced_duration=1.0,
    )
    data = generate_datasets("furuta", seed=0, recipe=recipe, ground_truth="mujoco")
    arrays = {}
    for loss in ("prop",):  # L_prop = L_Iτ + λ·L_traj: both losses' code in one training
        config = TrainSettings.for_system(
            "furuta", epochs=(12,), horizons=(2,), seed=0, progress=False, checkpoint_every=10**9
        )
        model, _ = train("dln", "furuta", loss, data["train"], config, forced_trajs=data["scale_fit"])
        leaves = jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array))
        arrays[loss] = np.concatenate([np.ravel(np.asarray(a, dtype=np.float64)) for a in leaves])
    np.savez(out, **arrays)
    (out.parent / (out.stem + ".json")).write_text(json.dumps(numerics()))


def digest(arrays: dict) -> str:
    h = hashlib.sha256()
    for key in sorted(arrays):
        h.update(np.ascontiguousarray(arrays[key]).tobytes())
    return h.hexdigest()[:16]


def run_setting(
    pinned: bool, cap: str | None, cores: int | None, blas: str | None, out: Path, numpy_avx512_off: bool = False
) -> dict:
    """One training in a fresh process as ``(pinned, cap, cores, blas, numpy_avx512_off)`` say;
    its parameters."""
    env = _environment(pinned, cap, blas, numpy_avx512_off)
    _run_python([__file__, "--one", str(out)], env, cores, timeout=900)
    with np.load(out) as f:
        arrays = {k: f[k] for k in f.files}
    return {"arrays": arrays, "numerics": json.loads((out.parent / (out.stem + ".json")).read_text())}


def run_all() -> dict:
    rows, reference = [], None
    with tempfile.TemporaryDirectory() as tmp:
        for i, (label, pinned, cap, cores, blas, numpy_off) in enumerate(SETTINGS):
            r = run_setting(pinned, cap, cores, blas, Path(tmp) / f"run{i}.npz", numpy_off)
            arrays = r["arrays"]
            if reference is None:
                reference = arrays
            rel = max(
                float(np.max(np.abs(arrays[k] - reference[k]) / np.maximum(np.abs(reference[k]), 1e-300)))
                for k in arrays
            )
            rows.append(
                {
                    "label": label,
                    "pinned": pinned,
                    "xla_cap": cap,
                    "cores": cores,
                    "openblas_coretype": blas,
                    "numpy_avx512_off": numpy_off,
                    "xla_flags_seen": r["numerics"]["xla_flags"],
                    "digest": digest(arrays),
                    "max_rel_diff_vs_reference": rel,
                }
            )
            print(rows[-1], flush=True)
    return {
        "machine": machine(),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "training": "Furuta DeLaN, 4 free MuJoCo trajectories of 1 s (seed 0), 12 epochs of 2-step windows, "
        "L_prop, scale fit on one forced trajectory",
        "rows": rows,
    }


QUICK = ROOT / "results" / "cpu_numerics" / "reproduce_quick.json"
# (label, XLA cap, cores, OPENBLAS_CORETYPE, NumPy without AVX-512): pinned, as the CI test's pair
QUICK_SETTINGS = [
    ("this machine (AVX-512), 2 cores", None, None, None, False),
    ("AVX2 machine, 1 core", "AVX2", 1, "Haswell", True),
]


def _environment(pinned: bool, cap: str | None, blas: str | None, numpy_avx512_off: bool) -> dict:
    # no compilation cache shared with other settings (a test session's): each compiles its own code
    unset = ("XLA_FLAGS", "PJRT_NPROC", "OPENBLAS_CORETYPE", "FURUTA_GYM_NATIVE_ISA", "JAX_COMPILATION_CACHE_DIR")
    env = {k: v for k, v in os.environ.items() if k not in unset and k != "NPY_DISABLE_CPU_FEATURES"}
    if numpy_avx512_off:
        env["NPY_DISABLE_CPU_FEATURES"] = NO_AVX512_NUMPY
    if not pinned:
        env["FURUTA_GYM_NATIVE_ISA"] = "1"
    if cap is not None:
        env["XLA_FLAGS"] = f"--xla_cpu_max_isa={cap}"
    if blas is not None:
        env["OPENBLAS_CORETYPE"] = blas
    env["FURUTA_GYM_COMPILATION_CACHE"] = "0"
    env["FURUTA_GYM_STEP_CACHE"] = "0"
    return env


def _affinity(cores: int | None):
    cpus = sorted(os.sched_getaffinity(0))[:cores] if cores else None
    return (lambda: os.sched_setaffinity(0, cpus)) if cpus else None


def _run_python(args: list[str], env: dict[str, str], cores: int | None, *, timeout: float) -> None:
    """``python ARGS`` in a fresh process with ``env`` on the first ``cores`` CPUs (all: None);
    a failure raises with the tail of its stderr."""
    proc = subprocess.run(
        [sys.executable, *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=_affinity(cores),
    )
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr[-3000:])


def _run_pinned(command: list[str], setting: tuple) -> None:
    """``furuta-gym COMMAND`` in a fresh process, pinned, as one of :data:`QUICK_SETTINGS`."""
    _label, cap, cores, blas, numpy_off = setting
    _run_python(["-m", "furuta_gym", *command], _environment(True, cap, blas, numpy_off), cores, timeout=7200)


def run_reproduce_quick() -> dict:
    """``furuta-gym reproduce --quick`` (every model of both tables, scaled down) as each pinned
    setting of :data:`QUICK_SETTINGS`; the digest of each run's tables.csv and of every model's
    metrics.json."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (label, cap, cores, blas, numpy_off) in enumerate(QUICK_SETTINGS):
            out = Path(tmp) / f"quick{i}"
            _run_pinned(
                ["reproduce", "--quick", "--no-figures", "--no-progress", "--out", str(out)],
                (label, cap, cores, blas, numpy_off),
            )
            metrics = {  # without "_seconds", the run's timings
                str(p.relative_to(out / "runs")): hashlib.sha256(
                    json.dumps({k: v for k, v in json.loads(p.read_text()).items() if k != "_seconds"}).encode()
                ).hexdigest()[:16]
                for p in sorted((out / "runs").rglob("metrics.json"))
            }
            rows.append(
                {
                    "label": label,
                    "xla_cap": cap,
                    "cores": cores,
                    "openblas_coretype": blas,
                    "numpy_avx512_off": numpy_off,
                    "tables_csv": hashlib.sha256((out / "tables.csv").read_bytes()).hexdigest()[:16],
                    "metrics": metrics,
                }
            )
            print(rows[-1]["label"], rows[-1]["tables_csv"], flush=True)
    return {
        "machine": machine(),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "rows": rows,
    }


DEMO = ROOT / "results" / "cpu_numerics" / "demo.json"
DEMO_SEED0 = ROOT / "results" / "demo_seeds" / "seed0.json"
# what the demo computes (its summary without where it wrote, how long it took, which numerics,
# and the printed table, whose wording may change while the numbers it prints do not)
DEMO_PARTS = ("tracking", "physics", "control")


def _demo_digest(summary: dict) -> str:
    parts = {k: summary[k] for k in DEMO_PARTS}
    parts["diagnose"] = {k: v for k, v in summary["diagnose"].items() if k != "log"}
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()[:16]


def run_demo() -> dict:
    """``furuta-gym demo`` at seed 0 (the README's command, no video) as each pinned setting of
    :data:`QUICK_SETTINGS`: the digest of what its summary reports, beside the committed
    demo-seeds row's (results/demo_seeds/seed0.json, made on this machine)."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, setting in enumerate(QUICK_SETTINGS):
            out, label = Path(tmp) / f"demo{i}", setting[0]
            _run_pinned(["demo", "--no-progress", "--no-video", "--seed", "0", "--out", str(out)], setting)
            summary = json.loads((out / "summary.json").read_text())
            rows.append({"label": label, "digest": _demo_digest(summary), "table": summary["table"]})
            print(label, rows[-1]["digest"], flush=True)
    return {
        "machine": machine(),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "demo_seeds_row": _demo_digest(json.loads(DEMO_SEED0.read_text())),
        "rows": rows,
    }


def demo_line(demo: dict) -> str:
    a, b = demo["rows"]
    same = a["digest"] == b["digest"]
    committed = sum(r["digest"] == demo["demo_seeds_row"] for r in demo["rows"])
    return (
        f"`furuta-gym demo` (seed 0, no video), pinned, on {a['label']} and on an emulated {b['label']} "
        f"({demo['date']}): its summary's digests `{a['digest']}` and `{b['digest']}` "
        f"({'the same bits' if same else '**different**'}); {committed} of 2 the committed demo-seeds seed-0 row's "
        f"(`{demo['demo_seeds_row']}`, docs/learning.md)."
    )


def quick_line(quick: dict) -> str:
    a, b = quick["rows"]
    line = (
        f"`furuta-gym reproduce --quick` (every model of both tables, scaled down), pinned, on {a['label']} and "
        f"on an emulated {b['label']} ({quick['date']}): tables.csv `{a['tables_csv']}` and `{b['tables_csv']}` "
        f"({'the same bits' if a['tables_csv'] == b['tables_csv'] else '**different**'})"
    )
    if "metrics" in a and "metrics" in b:
        same = sum(a["metrics"].get(k) == v for k, v in b["metrics"].items())
        line += f"; {same} of {len(b['metrics'])} models' metrics the same bits"
    return line + "."


def block(res: dict) -> str:
    ref = res["rows"][0]["digest"]
    lines = [
        f"{res['training']}; each setting a fresh process on {res['machine'].split(',')[0]} ({res['date']}), "
        "other machines emulated (XLA's instruction-set cap, CPU affinity, OpenBLAS's core type, NumPy's loops):",
        "",
        "| furuta_gym numerics | emulated machine | XLA_FLAGS given | OPENBLAS_CORETYPE | NumPy's AVX-512 loops "
        "| parameters' digest | same bits as the first row | largest relative difference |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in res["rows"]:
        flags = f"`--xla_cpu_max_isa={r['xla_cap']}`" if r["xla_cap"] else "none"
        lines.append(
            f"| {'pinned' if r['pinned'] else 'native'} | {r['label']} | {flags} | {r['openblas_coretype'] or 'unset'} "
            f"| {'off' if r.get('numpy_avx512_off') else 'on'} | `{r['digest']}` | {'yes' if r['digest'] == ref else 'no'} | {r['max_rel_diff_vs_reference']:.1e} |"
        )
    if QUICK.is_file():
        lines += ["", quick_line(json.loads(QUICK.read_text()))]
    if DEMO.is_file():
        lines += ["", demo_line(json.loads(DEMO.read_text()))]
    lines += [
        "",
        "Made by `python studies/cpu_numerics.py` (results/cpu_numerics/; `--reproduce-quick` and `--demo` the lines above); "
        "the CI test is tests/test_numerics.py.",
    ]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare the docs block only; exit 1 if stale")
    ap.add_argument("--one", type=Path, help="(child) run one training here and save its parameters")
    ap.add_argument("--reproduce-quick", action="store_true", help="run reproduce --quick pinned on two machines")
    ap.add_argument("--demo", action="store_true", help="run furuta-gym demo pinned on two machines")
    ap.add_argument("--render", action="store_true", help="rewrite the docs block from the committed results")
    args = ap.parse_args()
    if args.one is not None:
        tiny_training(args.one)
        return 0
    if args.reproduce_quick:
        QUICK.write_text(json.dumps(run_reproduce_quick(), indent=2) + "\n")
    elif args.demo:
        DEMO.write_text(json.dumps(run_demo(), indent=2) + "\n")
    elif not (args.check or args.render):
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(json.dumps(run_all(), indent=2) + "\n")
    res = json.loads(RESULTS.read_text())
    text = fill_block(DOC.read_text(), NAME, block(res), where=DOC)
    return update(DOC, text, args.check, "run python studies/cpu_numerics.py")


if __name__ == "__main__":
    sys.exit(main())
