"""Choose L_Iτ's quadrature rule for the reproduction's L_prop runs on validation data, never on the
test sets the reproduction reports.

Every rule trains each L_prop model with the full reproduction recipe (the same data, seed 0, the
same epochs and μ as ``furuta-gym reproduce``; only ``TrainConfig.quadrature`` differs — it also
sets the rule of the Furuta's scale fit). Every model then predicts the trajectories of the
*validation* draw (the test recipes generated with seed 100; the test sets use 0) and the mean
open-loop prediction log10 RMSE over sets and state variables is the criterion, as for μ
(bench/select_augmentation_weight.py). The rule goes into
:data:`furuta_gym.training.reproduce.REPRODUCE_QUADRATURE` by hand.

    python bench/select_quadrature.py --system furuta --kinds dln aph adln --rules simpson hermite \\
        --reuse results/reproduce

``--reuse DIR``: a run of DIR (a reproduction's output) whose recorded settings are exactly a
candidate's is copied in instead of trained again (the reproduction then reuses it as it would
its own). Writes ``OUT/<system>.md`` / ``.json``; runs live under ``OUT/<system>_<kind>/<rule>``.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import platform
import shutil
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from select_augmentation_weight import _run_dir, _score, parse_selection_args


def _config(system: str, kind: str, rule: str):
    from furuta_gym.training.reproduce import ReproduceConfig

    return ReproduceConfig(systems=(system,), pairs=((kind, "prop"),), train_overrides={"quadrature": rule},
                           figures=False, progress=False, jobs=1)


def _train(system: str, kind: str, rule: str, out: Path) -> None:
    import furuta_gym
    from furuta_gym.training.reproduce import reproduce

    furuta_gym.enable_x64()
    reproduce(out, _config(system, kind, rule), command=f"bench/select_quadrature.py {system} {kind} {rule}",
              log=lambda msg: None)


def _copy_matching_run(source: Path, system: str, kind: str, rule: str, out: Path) -> bool:
    """Copy ``source``'s run of this model into ``out`` if it was trained with exactly the
    candidate's settings (the reproduction's own comparison decides); True if ``out`` holds it."""
    from furuta_gym.training.reproduce import _default_hparams, _same_settings, training_config

    src = _run_dir(source, system, kind)
    dst = _run_dir(out, system, kind)
    if not (src / "model.eqx").exists() or not (src / "reproduce_config.json").exists():
        return False
    if dst.exists():  # copied by an earlier invocation?
        return (dst / "model.eqx").exists() and (dst / "model.eqx").read_bytes() == (src / "model.eqx").read_bytes()
    tcfg = training_config(system, _config(system, kind, rule), 0, "prop", kind).to_json()
    tcfg.pop("progress", None)
    current = {"system": system, "model": kind, "loss": "prop", "seed": 0, "train": tcfg,
               "model_hparams": _default_hparams(system, kind)}
    saved = json.loads((src / "reproduce_config.json").read_text())
    if not _same_settings(saved, json.loads(json.dumps(current))):
        return False
    dst.mkdir(parents=True)
    for name in ("model.eqx", "metrics.json", "reproduce_config.json", "history.json"):
        if (src / name).exists():
            shutil.copy2(src / name, dst / name)
    return True


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--system", required=True, choices=("furuta", "nmsd"))
    parser.add_argument("--kinds", nargs="+", default=["dln", "aph", "adln"], choices=("dln", "aph", "adln"))
    parser.add_argument("--rules", nargs="+", default=["simpson", "hermite"],
                        choices=("trapezoid", "simpson", "hermite"))
    parser.add_argument("--reuse", type=Path, default=None, help="a reproduction's output to copy matching runs from")
    args = parse_selection_args(parser, argv, "results/quadrature")

    import furuta_gym
    from furuta_gym.training.reproduce import _machine

    furuta_gym.enable_x64()
    machine = _machine()
    candidates = [(kind, rule, args.out / f"{args.system}_{kind}" / rule) for kind in args.kinds for rule in args.rules]
    copied = [(k, r) for k, r, out in candidates
              if args.reuse is not None and _copy_matching_run(args.reuse, args.system, k, r, out)]
    # spawn, not fork: comparing settings above already ran JAX, whose threads a forked child
    # would inherit mid-flight (it deadlocked)
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        list(pool.map(_train, *zip(*[(args.system, k, r, out) for k, r, out in candidates])))
    rows = {}
    for kind in args.kinds:
        runs = {rule: out for k, rule, out in candidates if k == kind}
        scores = _score(args.system, kind, runs, args.validation_seed)
        for rule, out in runs.items():
            metrics = json.loads((_run_dir(out, args.system, kind) / "metrics.json").read_text())
            scores[rule]["train_seconds"] = metrics["_seconds"]["train"]
            scores[rule]["reused_from"] = str(args.reuse) if (kind, rule) in copied else None
        rows[kind] = scores
    sets = list(next(iter(next(iter(rows.values())).values()))["sets"])
    names = list(next(iter(next(iter(rows.values())).values()))["sets"][sets[0]])
    lines = [
        f"# L_Iτ quadrature for the {args.system} L_prop runs, chosen on validation data",
        "",
        f"`python bench/select_quadrature.py --system {args.system} --kinds {' '.join(args.kinds)} "
        f"--rules {' '.join(args.rules)} --validation-seed {args.validation_seed}"
        + (f" --reuse {args.reuse}" if args.reuse else "") + "`, "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {machine.get('cpu', platform.machine())}, "
        f"{machine['cpu_count']} cores. Training seconds from each run's metrics.json (runs trained "
        "beside others are slower than alone).",
        "",
        f"Open-loop prediction log10 RMSE on the validation draw (seed {args.validation_seed}; the "
        "reported test sets are seed 0 and take no part in the choice). Lower is better; the mean is "
        "the criterion.",
        "",
        "| model | rule | " + " | ".join(f"{s} {n}" for s in sets for n in names) + " | mean | train s |",
        "|---|---|" + "---:|" * (len(sets) * len(names) + 2),
    ]
    chosen = {}
    for kind, scores in rows.items():
        best = min(scores, key=lambda r: scores[r]["mean"])
        chosen[kind] = best
        for rule, sc in scores.items():
            cells = [sc["sets"][s][n] for s in sets for n in names]
            text = " | ".join(c if isinstance(c, str) else f"{c:.2f}" for c in cells)
            mark = " ← lower" if rule == best else ""
            reused = " (reused)" if sc["reused_from"] else ""
            lines.append(f"| {kind} | {rule}{reused} | {text} | **{sc['mean']:.3f}**{mark} | {sc['train_seconds']:.0f} |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.system}.md").write_text("\n".join(lines) + "\n")
    (args.out / f"{args.system}.json").write_text(json.dumps(
        {"system": args.system, "validation_seed": args.validation_seed, "lower": chosen,
         "scores": rows}, indent=1) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
