"""Wall time of the diagnosis with its prediction-first finish on the 15 shipped QUBE runs, the
code before a change and after it, side by side in one run; rewrites its section of BENCHMARKS.md.

The README's command (``furuta-gym diagnose qube --system furuta --skip 0.5 --window 0.1
--oe-windows 64``) with ``--prediction-first``, as ``diagnose(..., finish="prediction")``: each
timing is a fresh process, from the loaded runs to the returned result, with JAX's persistent
compilation cache on as the command turns it on: each version's first run compiles into an empty
cache folder, its later runs find what that one stored. The two versions run in turn (before,
after, before, ...), so the machine's load falls on both alike; each run's 1-minute load
average and CPU seconds are recorded. The
code before is ``--before COMMIT`` and the code after ``--after COMMIT`` (HEAD by default), each
checked out into build/ (a git worktree): committed code only, whatever the working tree holds. The results of both are compared (effects, statuses, every number) and the after's
with the committed ``docs/diagnose_qube.json``. ``mujoco.sysid``'s fit time is read from the
head-to-head's committed results, with the diagnosis' on the same runs and core.

    python bench/diagnose_speed.py --before COMMIT [--after COMMIT] [--repeats 2]   # measure
    python bench/diagnose_speed.py [--check]   # the section from the committed results (or only compare)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _generated import ROOT, machine, write_section

RESULTS = ROOT / "results" / "diagnose_speed.json"
COMMITTED = ROOT / "docs" / "diagnose_qube.json"
HEAD_TO_HEAD = ROOT / "results" / "head_to_head"
START, END = "<!-- diagnose_speed:start -->", "<!-- diagnose_speed:end -->"
TARGET_SECONDS = 60.0
#: the package's folders as installed (pyproject.toml's package-dir): a checkout's import tree
MAPPED = {"models": "models", "controllers": "controllers", "assets": "assets"}

WORKER = """
import json, os, sys, time
if os.environ.get("DIAGNOSE_SPEED_TREE"):  # that tree's code, not the editable install's finder
    sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in getattr(f, "__module__", "")]
    sys.path.insert(0, os.environ["DIAGNOSE_SPEED_TREE"])
import furuta_gym
furuta_gym.enable_x64()
if os.environ.get("JAX_COMPILATION_CACHE_DIR"):  # as the diagnose command turns it on
    from furuta_gym.cli._cache import enable_compilation_cache
    enable_compilation_cache()
from jax._src import monitoring
from furuta_gym.datasets import load_qube_closed_loop
from furuta_gym.diagnose import diagnose
compiles = [0]
def count(event, duration, **_):
    compiles[0] += event == "/jax/core/compile/backend_compile_duration"
monitoring.register_event_duration_secs_listener(count)
runs = load_qube_closed_loop(list(range(1, 16)), skip_seconds=0.5)
load = os.getloadavg()[0]
t0, c0 = time.perf_counter(), os.times()
res = diagnose(runs, "furuta", window=0.1, oe_max_windows=64, finish="prediction")
wall, c1 = time.perf_counter() - t0, os.times()
cpu = c1.user + c1.system - c0.user - c0.system
doc = {"wall_seconds": wall, "cpu_seconds": cpu, "load_start": load, "load_end": os.getloadavg()[0], "compiles": compiles[0],
       "package": furuta_gym.__file__, "result": res.to_json()}
json.dump(doc, open(sys.argv[1], "w"), default=float)
"""


def import_tree(commit: str) -> Path:
    """``commit`` checked out under build/ with the package's mapped folders linked into it, so
    that ``import furuta_gym`` from that folder is that commit's code, whole."""
    base = ROOT / "build" / "diagnose_speed"
    checkout, tree = base / f"checkout-{commit}", base / f"tree-{commit}"
    if not checkout.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(checkout), commit], cwd=ROOT, check=True)
    if not tree.exists():
        (tree / "furuta_gym").parent.mkdir(parents=True, exist_ok=True)
        os.symlink(checkout / "furuta_gym", tree / "furuta_gym")
        for name, src in MAPPED.items():  # furuta_gym/<name> -> <src> as installed
            link = checkout / "furuta_gym" / name
            if not link.exists():
                os.symlink(checkout / src, link)
    return tree


def remove_tree(commit: str) -> None:
    """Undo :func:`import_tree`: the worktree (with the links made in it) and the link tree."""
    base = ROOT / "build" / "diagnose_speed"
    subprocess.run(["git", "worktree", "remove", "--force", str(base / f"checkout-{commit}")], cwd=ROOT, check=False)
    shutil.rmtree(base / f"tree-{commit}", ignore_errors=True)


def timed_run(tree: Path, cache: Path) -> dict:
    """One diagnosis in a fresh process, importing the package from ``tree``, with JAX's
    persistent compilation cache in ``cache`` (as ``furuta-gym diagnose`` turns it on)."""
    env = {**os.environ, "DIAGNOSE_SPEED_TREE": str(tree), "JAX_COMPILATION_CACHE_DIR": str(cache)}
    env.pop("FURUTA_GYM_COMPILATION_CACHE", None)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.json"
        subprocess.run([sys.executable, "-c", WORKER, str(out)], env=env, check=True, cwd=tmp)
        return json.loads(out.read_text())


#: a value this close to zero is a term fitted to nothing (a damping of 1e-24): it has no scale to compare
NOTHING = 1e-12


def largest_difference(a, b, path: str = "") -> tuple[float, list[str]]:
    """Largest relative difference of two JSON documents' numbers (two within :data:`NOTHING` of
    zero count as equal, as against the committed JSON), and where other values differ."""
    if isinstance(a, dict) and isinstance(b, dict) and set(a) == set(b):
        parts = [largest_difference(a[k], b[k], f"{path}/{k}") for k in a]
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        parts = [largest_difference(x, y, f"{path}[{i}]") for i, (x, y) in enumerate(zip(a, b, strict=True))]
    elif isinstance(a, float) and isinstance(b, float):
        scale = max(abs(a), abs(b))
        return (abs(a - b) / scale if scale > NOTHING else 0.0), []
    else:
        return 0.0, ([] if a == b else [path])
    return max([0.0] + [p[0] for p in parts]), [w for p in parts for w in p[1]]


def against_committed(result: dict) -> dict:
    """The after's diagnosis against the committed docs/diagnose_qube.json: the same effects with
    the same statuses, and the largest relative difference of a found coefficient or parameter."""
    committed = json.loads(COMMITTED.read_text())
    key = lambda d: sorted((e["name"], e["joint"], e["status"]) for e in d["effects"])  # noqa: E731
    found = {(e["name"], e["joint"]): e["coefficient"] for e in committed["effects"] if e["significant"]}
    pairs = [(e["coefficient"], found[(e["name"], e["joint"])]) for e in result["effects"] if e["significant"]]
    pairs += [(v, committed["parameters_after"][k]) for k, v in result["parameters_after"].items()]
    pairs = [(a, b) for a, b in pairs if max(abs(a), abs(b)) > NOTHING]
    return {
        "same_effects_and_statuses": key(result) == key(committed),
        "largest_relative_difference": max(abs(a - b) / max(abs(a), abs(b), 1e-300) for a, b in pairs),
    }


def short(commit: str) -> str:
    return subprocess.run(
        ["git", "rev-parse", "--short", commit], cwd=ROOT, text=True, capture_output=True
    ).stdout.strip()


def measure(before: str, after: str, repeats: int) -> dict:
    """Both commits' code (never the working tree's uncommitted edits), in turn."""
    before, after = short(before), short(after)
    trees = {"before": import_tree(before), "after": import_tree(after)}
    caches = {label: ROOT / "build" / "diagnose_speed" / f"jax-cache-{label}" for label in trees}
    for cache in caches.values():  # the first run of each version starts from an empty cache
        shutil.rmtree(cache, ignore_errors=True)
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    for _ in range(repeats):
        for label, where in trees.items():
            runs[label].append(timed_run(where, caches[label]))
            r = runs[label][-1]
            print(
                f"{label}: {r['wall_seconds']:.1f} s (load {r['load_start']:.1f}), {r['compiles']} compiles", flush=True
            )
    for commit in (before, after):  # the checkouts are the bench's own: leave none behind
        remove_tree(commit)
    same, differing = largest_difference(runs["before"][0]["result"], runs["after"][0]["result"])
    return {
        "machine": machine(),
        "host": platform.node(),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "before_commit": before,
        "after_commit": after,
        "runs": {
            k: [{f: r[f] for f in ("wall_seconds", "cpu_seconds", "load_start", "load_end", "compiles")} for r in v]
            for k, v in runs.items()
        },
        "before_vs_after": {"largest_relative_difference": same, "other_values_differing": differing},
        "after_vs_committed": against_committed(runs["after"][0]["result"]),
    }


def _sysid_line() -> str:
    """mujoco.sysid's fit time beside the diagnosis' on the same runs and core (the head-to-head)."""
    try:
        sysid = json.loads((HEAD_TO_HEAD / "sysid.json").read_text())
        ours = json.loads((HEAD_TO_HEAD / "diagnosed_prediction.json").read_text())
        summary = json.loads((HEAD_TO_HEAD / "summary.json").read_text())
    except FileNotFoundError:
        return "No head-to-head results (results/head_to_head/) to set mujoco.sysid's time beside."
    band = ", the finish's dead band trial included" if ours["prediction_finish"].get("dead_band") else ""
    return (
        f"Beside it, from the head-to-head's committed results (results/head_to_head/, {summary['date']}, "
        f"{summary['cpu']}; fit on runs 1–10 only{band}): mujoco.sysid's fit "
        f"{sysid['wall_seconds']:.0f} s, the diagnosis with its prediction-first finish "
        f"{ours['wall_seconds']:.0f} s."
    )


def section(doc: dict) -> str:
    rows = []
    for i in range(len(doc["runs"]["before"])):
        for label in ("before", "after"):
            r = doc["runs"][label][i]
            rows.append(
                f"| {label} ({doc[label + '_commit']}) | {i + 1} ({'empty' if i == 0 else 'warm'}) | "
                f"{r['wall_seconds']:.1f} | {r['cpu_seconds']:.1f} | {r['load_start']:.1f} → {r['load_end']:.1f} "
                f"| {r['compiles']} |"
            )
    best = {k: min(r["wall_seconds"] for r in v[:1]) for k, v in doc["runs"].items()}
    warm = {k: min([r["wall_seconds"] for r in v[1:]] or [float("nan")]) for k, v in doc["runs"].items()}
    diff, committed = doc["before_vs_after"], doc["after_vs_committed"]
    same = (
        "bit for bit"
        if diff["largest_relative_difference"] == 0 and not diff["other_values_differing"]
        else (
            f"to a relative {diff['largest_relative_difference']:.1e} (other values differing: {diff['other_values_differing']})"
        )
    )
    return "\n".join(
        [
            START,
            "## Diagnosis wall time, 15 shipped runs with the prediction-first finish (`bench/diagnose_speed.py`)",
            "",
            f"{doc['date']}, {doc['machine']}. `diagnose(load_qube_closed_loop(1–15, skip_seconds=0.5), "
            '"furuta", window=0.1, oe_max_windows=64, finish="prediction")`, each run a fresh process '
            "with JAX's persistent compilation cache as `furuta-gym diagnose` turns it on (one folder per "
            "version, empty before its first run), the two versions in turn on both cores; the 1-minute "
            "load average at each run's start and end is the machine's (shared), part of the number.",
            "",
            "| code | run (compilation cache) | wall s | CPU s | load | JAX compile events |",
            "|---|---|---:|---:|---|---:|",
            *rows,
            "",
            f"Compiling from an empty cache: before {best['before']:.1f} s, after {best['after']:.1f} s "
            f"({best['before'] / best['after']:.2f}×); with the cache its first run filled: before "
            f"{warm['before']:.1f} s, after {warm['after']:.1f} s (target ≤ {TARGET_SECONDS:.0f} s on 2 cores). "
            "CPU seconds (both cores, all threads) are the load-robust part of the comparison. The two "
            f"versions' results agree {same}. Against the committed docs/diagnose_qube.json: same "
            f"effects and statuses: {'yes' if committed['same_effects_and_statuses'] else 'NO'}; found "
            f"coefficients and parameters within a relative {committed['largest_relative_difference']:.1e} "
            "(the code before this change gives the same; the JSON is from earlier library versions).",
            "",
            _sysid_line(),
            END,
        ]
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", help="the commit to compare with (its code checked out under build/)")
    ap.add_argument("--after", default="HEAD", help="the commit measured against it (default HEAD)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--check", action="store_true", help="only compare BENCHMARKS.md with the results file")
    args = ap.parse_args(argv)
    if args.before and not args.check:  # without --before: the section from the committed results
        RESULTS.write_text(json.dumps(measure(args.before, args.after, args.repeats), indent=1) + "\n")
    return write_section(section(json.loads(RESULTS.read_text())), START, END, check=args.check)


if __name__ == "__main__":
    sys.exit(main())
