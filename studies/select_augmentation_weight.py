"""Choose μ, the weight of L_prop's minimum-norm term μ·P_a, per system and model kind on
validation data: never on the test sets the reproduction reports.

Each candidate μ trains the model with the full reproduction recipe (the same training data,
seed 0, the same epochs as ``furuta-gym reproduce``) as a *validation* run
(``ReproduceSettings(split="validation")``): the Furuta scale is fitted on ``val_scale_fit`` and the
model predicts the validation datasets only (``generate_validation``: their own excitation and
initial states, no sample following a test trajectory; docs/reproduce.md) — no test set is
generated, scored or stored. The criterion is what a user could measure on held-out data: the
mean over validation sets and state variables of the open-loop prediction log10 RMSE (a diverged
prediction counts as +2). The smallest wins; the choice goes into the recipe by hand.

    python studies/select_augmentation_weight.py --system furuta --kind adln --weights 0.01 0.1 1 10

Writes ``OUT/<system>_<kind>.md`` (and ``.json``) with one row per μ; trained runs live under
``OUT/<system>_<kind>/mu_<μ>`` and are reused when the script runs again.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

DIVERGED_SCORE = 2.0


def _config(system: str, kind: str, weight: float):
    """The validation run of one candidate μ."""
    from furuta_gym.training.reproduce import ReproduceSettings

    return ReproduceSettings(
        systems=(system,),
        pairs=((kind, "prop"),),
        split="validation",
        train_overrides={"augmentation_weight": weight},
        figures=False,
        progress=False,
        jobs=1,
    )


def _train(system: str, kind: str, weight: float, out: Path) -> None:
    import furuta_gym
    from furuta_gym.training.reproduce import reproduce

    furuta_gym.enable_x64()
    reproduce(
        out,
        _config(system, kind, weight),
        command=f"studies/select_augmentation_weight.py μ={weight!r}",
        log=lambda msg: None,
    )


def _run_dir(out: Path, system: str, kind: str, seed: int = 0) -> Path:
    """Where ``furuta-gym reproduce`` writes a candidate folder's L_prop run of model ``seed``."""
    return out / "runs" / system / f"{kind}_prop" / f"seed{seed}"


def _score(system: str, kind: str, runs: dict, seeds: tuple[int, ...] = (0,)) -> dict:
    """Each candidate's validation score, read from its validation runs' metrics.json: per model
    seed the mean over sets and state variables, then averaged over ``seeds`` (``"mean"``, the
    criterion; ``"seed_means"`` each seed's), a diverged prediction counted as +2; the cells
    (``"sets"``) are means over the seeds."""
    import numpy as np

    from furuta_gym.systems import get_spec
    from furuta_gym.training.metrics import DIVERGED
    from furuta_gym.training.reproduce import FAILED, VALIDATION_SETS

    names = get_spec(system).state_names
    scores = {}
    for key, out in runs.items():
        per_seed = []
        for seed in seeds:
            metrics = json.loads((_run_dir(out, system, kind, seed) / "metrics.json").read_text())
            per_seed.append({label: {k: metrics[label][k] for k in names} for label in VALIDATION_SETS[system]})

        def value(v):
            return DIVERGED_SCORE if v in (DIVERGED, FAILED) else float(v)

        # a cell shows DIVERGED if any seed's prediction diverged; the criterion counts it as +2
        sets = {
            label: {
                k: DIVERGED
                if any(p[label][k] in (DIVERGED, FAILED) for p in per_seed)
                else float(np.mean([float(p[label][k]) for p in per_seed]))
                for k in per_seed[0][label]
            }
            for label in per_seed[0]
        }
        seed_means = [float(np.mean([value(v) for cells in p.values() for v in cells.values()])) for p in per_seed]
        scores[key] = {"mean": float(np.mean(seed_means)), "seed_means": seed_means, "sets": sets}
    return scores


def parse_selection_args(parser: argparse.ArgumentParser, argv, default_out: str) -> argparse.Namespace:
    """The arguments every selection script shares: the output folder and the jobs."""
    parser.add_argument("--out", type=Path, default=Path(default_out))
    parser.add_argument("--jobs", type=int, default=2)
    return parser.parse_args(argv)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--system", required=True, choices=("furuta", "nmsd"))
    parser.add_argument("--kind", required=True, choices=("adln", "aph"))
    parser.add_argument("--weights", type=float, nargs="+", default=[0.01, 0.1, 1.0, 10.0])
    args = parse_selection_args(parser, argv, "results/augmentation_weight")

    import furuta_gym
    from furuta_gym.training.reproduce import machine_info

    furuta_gym.enable_x64()
    machine = machine_info()
    folder = args.out / f"{args.system}_{args.kind}"
    runs = {w: folder / f"mu_{w:g}" for w in args.weights}
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        list(pool.map(_train, [args.system] * len(runs), [args.kind] * len(runs), runs, runs.values()))
    # what each model cost when it was trained (a run reused from an earlier invocation included)
    seconds = {
        w: json.loads((_run_dir(out, args.system, args.kind) / "metrics.json").read_text())["_seconds"]["train"]
        for w, out in runs.items()
    }
    scores = _score(args.system, args.kind, runs)
    best = min(scores, key=lambda w: scores[w]["mean"])
    sets = list(next(iter(scores.values()))["sets"])
    names = list(next(iter(scores.values()))["sets"][sets[0]])
    lines = [
        f"# μ for {args.kind} on {args.system}, chosen on validation data",
        "",
        f"`python studies/select_augmentation_weight.py --system {args.system} --kind {args.kind} "
        f"--weights {' '.join(f'{w:g}' for w in args.weights)}`, "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {machine.get('cpu', platform.machine())}, "
        f"{machine['cpu_count']} cores; training {round(sum(seconds.values()))} s summed over the candidates "
        "(times from each run's metrics.json).",
        "",
        "Open-loop prediction log10 RMSE on the validation datasets (their own excitation; the "
        "test sets are never generated or scored). Lower is better; the mean is the criterion.",
        "",
        "| μ | " + " | ".join(f"{s} {n}" for s in sets for n in names) + " | mean |",
        "|---|" + "---:|" * (len(sets) * len(names) + 1),
    ]
    for w, sc in scores.items():
        cells = [sc["sets"][s][n] for s in sets for n in names]
        text = " | ".join(c if isinstance(c, str) else f"{c:.2f}" for c in cells)
        mark = " ← chosen" if w == best else ""
        lines.append(f"| {w:g} | {text} | **{sc['mean']:.3f}**{mark} |")
    folder.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.system}_{args.kind}.md").write_text("\n".join(lines) + "\n")
    (args.out / f"{args.system}_{args.kind}.json").write_text(
        json.dumps(
            {
                "system": args.system,
                "kind": args.kind,
                "split": "validation",
                "chosen": best,
                "scores": {f"{w:g}": sc for w, sc in scores.items()},
                "train_seconds": {f"{w:g}": s for w, s in seconds.items()},
            },
            indent=1,
        )
        + "\n"
    )
    print("\n".join(lines))


if __name__ == "__main__":
    main()
