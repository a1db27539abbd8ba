"""Choose one option of the reproduction's recipe on validation data, never on the test sets the
reproduction reports: a training setting (``--train NAME VALUE …``, e.g. L_Iτ's quadrature) or a
model option (``--model NAME VALUE …``, e.g. F_a's ``odd_in_velocity``).

Every value trains each named L_prop model with the full reproduction recipe (the same training
data, model seed 0, epochs and μ as ``furuta-gym reproduce``; only that option differs) as a
*validation* run (``split="validation"``: scale fitted on ``val_scale_fit``, scored on the
validation datasets, which share no excitation with the test sets; no test set is generated,
scored or stored), and the mean open-loop prediction log10 RMSE over sets and state variables is
the criterion, as for μ (studies/select_augmentation_weight.py). ``--seeds N`` trains model seeds 0 … N−1
of every candidate and takes the mean over them: one run each cannot tell options apart whose
difference is smaller than the seeds' spread (the Furuta augmented DeLaN's validation means of
three seeds, fine-tuned at 1e-3: −0.79, −0.79, −0.91).

With several seeds the first value is the recipe's current one, and another replaces it only if
it scores lower on *every* model seed (seed by seed: the same seed's data order and
initialisation, so the pair differs by the option alone); among those the lowest mean wins
(:func:`choose`). Seeds are trained in turn, and a value beaten on one seed is not trained on
the next: it can no longer be chosen, so the decision is the one all seeds would give, at a
third of the cost for a value beaten on seed 0 (its table row says where it stopped). A mean
lower by less than the seeds' spread, with one seed against, is a tie, and a tie keeps what the
recipe has: that is how the Furuta's DeLaN and APHYNITY kept Simpson's
rule when the Hermite rule's means were lower by 0.05 and 0.03 (results/quadrature_seeds). The
choice goes into the code by hand.

    python studies/select_option.py --system furuta --kinds dln aph adln \
        --train quadrature simpson hermite --seeds 3 --out results/selection/quadrature
    python studies/select_option.py --system nmsd --kinds adln --model odd_in_velocity false true \
        --seeds 3 --out results/selection/force_parity

The candidates train in a local pool of ``--jobs`` processes or, with ``--executor ray
[--address ADDR] [--cpus-per-task N]``, each candidate × seed as a Ray task, exactly as
``furuta-gym reproduce`` trains its models (its workers,
:func:`furuta_gym.training.reproduce.worker_pool`): a run already finished is reused by its
recorded settings, one whose worker was lost is retried and resumes from its saved state, and
the folders and the decision are the same. ``--quick`` trains them as ``reproduce --quick`` does
(scaled-down data, a few epochs): a check of the pipeline, never evidence for the recipe.

Values are JSON where they parse (false, 0.1) and strings otherwise. ``--reuse DIR …``: a run of
a DIR (a folder holding ``runs/``: one candidate of another selection,
``OUT/<system>_<kind>/<value>``, or a validation reproduction; the first that has one) whose
recorded settings are exactly a candidate's, split and seed included, is copied in instead of
trained again. Writes
``OUT/<system>.md`` / ``.json``; runs live under ``OUT/<system>_<kind>/<value>``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import shutil
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

from select_augmentation_weight import _run_dir, _score, parse_selection_args


def _parse(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _config(
    system: str, kind: str, where: str, name: str, value, seeds: int | tuple[int, ...] = 1, quick: bool = False
):
    """The reproduction config of one candidate: ``where`` is "train" or "model"; model seeds
    0 … ``seeds`` − 1, or the tuple given; ``quick``: as ``furuta-gym reproduce --quick`` trains."""
    from furuta_gym.training.reproduce import ReproduceSettings

    override = {name: value}
    seeds = tuple(range(seeds)) if isinstance(seeds, int) else tuple(seeds)
    return ReproduceSettings(
        quick=quick,
        systems=(system,),
        pairs=((kind, "prop"),),
        seeds=seeds,
        figures=False,
        progress=False,
        jobs=1,
        split="validation",
        train_overrides=override if where == "train" else None,
        model_overrides=override if where == "model" else None,
    )


def _train(out: Path, config, command: str) -> None:
    """One candidate's runs (a worker's task): the reproduction of ``config`` into ``out``."""
    from furuta_gym.training.reproduce import reproduce

    furuta_gym.enable_x64()
    reproduce(out, config, command=command, log=lambda msg: None)


def _copy_matching_run(source: Path, system: str, kind: str, config, out: Path, seed: int = 0) -> bool:
    """Copy ``source``'s run of this model and ``seed`` into ``out`` if it was trained with exactly
    the candidate's settings (the reproduction's own comparison decides); True if ``out`` holds it."""
    from furuta_gym.training.reproduce import run_settings, same_settings

    src = _run_dir(source, system, kind, seed)
    dst = _run_dir(out, system, kind, seed)
    if not (src / "model.eqx").exists() or not (src / "reproduce_config.json").exists():
        return False
    if dst.exists():  # copied by an earlier invocation?
        return (dst / "model.eqx").exists() and (dst / "model.eqx").read_bytes() == (src / "model.eqx").read_bytes()
    saved = json.loads((src / "reproduce_config.json").read_text())
    if not same_settings(saved, run_settings(system, kind, "prop", seed, config)):
        return False
    dst.mkdir(parents=True)
    for name in ("model.eqx", "metrics.json", "reproduce_config.json", "history.json"):
        if (src / name).exists():
            shutil.copy2(src / name, dst / name)
    return True


def choose(seed_means: dict[str, list[float]], several_seeds: bool | None = None) -> tuple[str, dict[str, dict]]:
    """The rule of ``--seeds N``: ``seed_means`` maps each value, the recipe's current one first,
    to its validation means per model seed, seeds 0, 1, … in order; a value beaten on a seed may
    stop there (its later seeds untrained). Returns the chosen value and, for every other value,
    its seed-by-seed differences from the first (``"differences"``, negative = better; as many as
    it has seeds) and whether it is better on every seed (``"every_seed"``). One seed keeps the
    plain lowest mean, unless ``several_seeds`` were asked for (and every value was beaten on
    seed 0, so that the recipe's value has only that one); by default, whether it has several."""
    values = list(seed_means)
    first = values[0]
    if not (len(seed_means[first]) > 1 if several_seeds is None else several_seeds):
        return min(values, key=lambda v: seed_means[v][0]), {}
    paired = {}
    for value in values[1:]:
        means = seed_means[value]
        if len(means) > len(seed_means[first]):
            raise ValueError(f"{value!r} has {len(means)} seed means, {first!r} has {len(seed_means[first])}")
        diff = [b - a for a, b in zip(seed_means[first], means, strict=False)]  # a value may have fewer seeds so far
        if len(means) < len(seed_means[first]) and (not diff or diff[-1] < 0):
            raise ValueError(
                f"{value!r} has {len(means)} seed means, {first!r} has "
                f"{len(seed_means[first])}, and it was not beaten on its last seed"
            )
        paired[value] = {
            "differences": diff,
            "every_seed": len(means) == len(seed_means[first]) and all(d < 0 for d in diff),
        }
    better = [v for v in values[1:] if paired[v]["every_seed"]]
    chosen = min(better, key=lambda v: float(np.mean(seed_means[v]))) if better else first
    return chosen, paired


def _seed_mean(system: str, kind: str, out: Path, seed: int) -> float:
    return _score(system, kind, {"run": out}, (seed,))["run"]["mean"]


def _train_in_turn(first: str, candidates, seeds: tuple[int, ...], train, seed_mean) -> dict:
    """Train seed by seed; a value beaten by ``first`` (the recipe's) on a seed is not trained on
    later ones. ``candidates``: (kind, value, out) triples; ``train(live, seed)`` trains the live
    ones' ``seed``, ``seed_mean(kind, out, seed)`` scores one run. Returns {(kind, value): the
    seeds it was trained on}."""
    trained = {(k, t): [] for k, t, _ in candidates}
    beaten = set()
    for seed in seeds:
        live = [c for c in candidates if c[:2] not in beaten]
        if seed > 0 and all(t == first for _, t, _ in live):
            break  # every other value is beaten: no later seed can change the choice
        train(live, seed)
        means = {(k, t): seed_mean(k, out, seed) for k, t, out in live}
        for k, t, _ in live:
            trained[(k, t)].append(seed)
            if t != first and means[(k, t)] >= means[(k, first)]:
                beaten.add((k, t))
    return trained


def _seed_columns(score: dict, pair: dict | None, seeds: int) -> str:
    """The table's per-seed columns of one value: its seed means, then its differences from the
    recipe's value (and where it stopped, beaten)."""
    means = score["seed_means"]
    spread = f"± {float(np.std(means, ddof=1)):.3f}" if len(means) > 1 else "one seed"
    text = f" {' / '.join(f'{m:.3f}' for m in means)} ({spread}) |"
    if pair is None:
        return text + " (the recipe's) |"
    text += f" {' / '.join(f'{d:+.3f}' for d in pair['differences'])}"
    if pair["every_seed"]:
        text += " (every seed better)"
    elif len(means) < seeds:
        text += f"; beaten on seed {len(means) - 1}, not trained on later seeds"
    return text + " |"


def _arguments(argv) -> argparse.Namespace:
    from furuta_gym.cli.reproduce import add_executor_arguments
    from furuta_gym.training.reproduce import ReproduceSettings

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--system", required=True, choices=("furuta", "nmsd"))
    parser.add_argument("--kinds", nargs="+", default=["dln", "aph", "adln"], choices=("dln", "aph", "adln"))
    option = parser.add_mutually_exclusive_group(required=True)
    option.add_argument("--train", nargs="+", metavar=("NAME", "VALUE"), help="a TrainSettings field and its values")
    option.add_argument("--model", nargs="+", metavar=("NAME", "VALUE"), help="a model option and its values")
    parser.add_argument(
        "--reuse",
        type=Path,
        nargs="+",
        default=[],
        help="folders holding runs/ (a candidate of another selection: OUT/<system>_<kind>/<value>) "
        "to copy matching runs from (the first that has one)",
    )
    parser.add_argument(
        "--seeds", type=int, default=1, help="model seeds per candidate (0 … N-1); the criterion is their mean"
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="candidates trained as `furuta-gym reproduce --quick` trains (scaled-down data, a few "
        "epochs): a check of the pipeline in minutes, never a choice for the recipe",
    )
    add_executor_arguments(parser)
    args = parse_selection_args(parser, argv, "results/selection")
    args.where = "train" if args.train else "model"
    args.name, *args.values = args.train or args.model
    if len(args.values) < 2:
        parser.error(f"--{args.where} {args.name}: give at least two values to choose between")
    if args.seeds < 1:
        parser.error(f"--seeds must be at least 1, got {args.seeds}")
    try:  # where the candidates train, checked as the reproduction checks its own
        args.workers = ReproduceSettings(
            systems=(args.system,),
            jobs=args.jobs,
            executor=args.executor,
            address=args.address,
            cpus_per_task=args.cpus_per_task,
        )
    except ValueError as exc:
        parser.error(str(exc))
    return args


@contextlib.contextmanager
def _workers(args):
    """The workers ``--executor`` names (the reproduction's own, :func:`worker_pool`); with
    ``--executor ray`` and no Ray installed, one line naming the extra before any work."""
    from furuta_gym.training.reproduce import worker_pool

    with contextlib.ExitStack() as stack:
        try:
            pool = stack.enter_context(worker_pool(args.workers))
        except ImportError as exc:
            raise SystemExit(f"studies/select_option.py: error: {exc}") from None
        yield pool


def _train_candidates(args) -> tuple[list, dict, dict]:
    """Copy the runs ``--reuse`` holds, train the others seed by seed, each candidate × seed one
    task of the workers. Returns the candidates (kind, value, config, out), {(kind, value): seeds
    trained} and {(kind, value): {seed: the folder its run was copied from}}."""
    seeds = tuple(range(args.seeds))
    candidates = [
        (
            kind,
            text,
            _config(args.system, kind, args.where, args.name, _parse(text), args.seeds, args.quick),
            args.out / f"{args.system}_{kind}" / text,
        )
        for kind in args.kinds
        for text in args.values
    ]
    configs = {(k, t): cfg for k, t, cfg, _ in candidates}
    with _workers(args) as pool:
        copied = {
            (k, t): {
                seed: str(src)
                for seed in seeds
                for src in [
                    next((r for r in args.reuse if _copy_matching_run(r, args.system, k, cfg, out, seed)), None)
                ]
                if src is not None
            }
            for k, t, cfg, out in candidates
        }

        def train(live, seed):
            tasks = [
                pool.submit(
                    _train,
                    (
                        pool.folder(out),
                        dataclasses.replace(configs[(k, t)], seeds=(seed,)),
                        f"studies/select_option.py {args.system} {k} {args.where} {args.name}={_parse(t)!r}",
                    ),
                    f"{args.system}_{k}/{t}/seed{seed}",  # the task's name: its run's folder
                )
                for k, t, out in live
            ]
            for task in tasks:  # in order, the first failure raised, as pool.map did
                pool.result(task)

        trained = _train_in_turn(
            args.values[0],
            [(k, t, out) for k, t, _, out in candidates],
            seeds,
            train,
            lambda k, out, seed: _seed_mean(args.system, k, out, seed),
        )
    return candidates, trained, copied


def _scores(args, candidates, trained, copied) -> dict[str, dict[str, dict]]:
    """{kind: {value: its validation score over the seeds it was trained on, with those seeds,
    its mean training seconds and where reused runs came from}}."""
    rows = {kind: {} for kind in args.kinds}
    for kind, text, _, out in candidates:
        own = tuple(trained[(kind, text)])
        score = _score(args.system, kind, {text: out}, own)[text]
        seconds = [
            json.loads((_run_dir(out, args.system, kind, seed) / "metrics.json").read_text())["_seconds"]["train"]
            for seed in own
        ]
        score["seeds"] = list(own)
        score["train_seconds"] = sum(seconds) / len(seconds)
        score["reused_from"] = {s: src for s, src in copied[(kind, text)].items() if s in own} or None
        rows[kind][text] = score
    return rows


def _header(args, machine: dict, sets: list, names: list) -> list[str]:
    several = args.seeds > 1
    first = args.values[0]
    return [
        f"# {args.name} for the {args.system} L_prop runs, chosen on validation data",
        "",
        f"`python studies/select_option.py --system {args.system} --kinds {' '.join(args.kinds)} "
        f"--{args.where} {args.name} {' '.join(args.values)}"
        + (f" --seeds {args.seeds}" if several else "")
        + (" --quick" if args.quick else "")
        + (f" --reuse {' '.join(map(str, args.reuse))}" if args.reuse else "")
        + (" --executor ray" if args.executor == "ray" else "")
        + f" --out {args.out}`, "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {machine.get('cpu', 'cpu')}, "
        f"{machine['cpu_count']} cores. Training seconds from each run's metrics.json (runs trained "
        "beside others are slower than alone)"
        + (
            f"; cells, mean and seconds are means over the model seeds a value was trained on "
            f"({', '.join(map(str, range(args.seeds)))} in turn; a value beaten on a seed is not trained on later "
            "ones), whose own means follow (± their standard deviation)"
            if several
            else ""
        )
        + ".",
        "",
        "Open-loop prediction log10 RMSE on the validation datasets (their own excitation; the test "
        "sets are never generated or scored). Lower is better; the mean is the criterion"
        + (f", and a value replaces the recipe's ({first}) only if it is lower on every model seed" if several else "")
        + ".",
        "",
        f"| model | {args.name} | "
        + " | ".join(f"{s} {n}" for s in sets for n in names)
        + " | mean |"
        + (f" seeds | seed by seed vs {first} |" if several else "")
        + " train s |",
        "|---|---|" + "---:|" * (len(sets) * len(names) + 2 + 2 * several),
    ]


def _decide(args, rows, sets: list, names: list) -> tuple[list[str], dict, dict]:
    """The table's rows, the chosen value and the lowest mean per kind (marks each score with its
    differences from the recipe's value)."""
    texts, several = args.values, args.seeds > 1
    lines, chosen, lowest = [], {}, {}
    for kind, scores in rows.items():
        # "lower" compares means over the same seeds: among the values trained on all of them
        full = [t for t in scores if len(scores[t]["seeds"]) == len(scores[texts[0]]["seeds"])]
        best = lowest[kind] = min(full, key=lambda t: scores[t]["mean"])
        chosen[kind], paired = choose({t: scores[t]["seed_means"] for t in texts}, several_seeds=several)
        for text, pair in paired.items():
            scores[text]["vs_first"] = pair
        for text, sc in scores.items():
            cells = [sc["sets"][s][n] for s in sets for n in names]
            cell_text = " | ".join(c if isinstance(c, str) else f"{c:.2f}" for c in cells)
            mark = " ← lower" if text == best else ""
            if several and text == chosen[kind]:
                mark += " ← chosen"
            reused = ""
            if sc["reused_from"]:
                reused = (
                    " (reused)"
                    if len(sc["reused_from"]) == len(sc["seeds"])
                    else f" (seed{'s' * (len(sc['reused_from']) > 1)} {', '.join(map(str, sc['reused_from']))} reused)"
                )
            per_seed = _seed_columns(sc, sc.get("vs_first"), args.seeds) if several else ""
            lines.append(
                f"| {kind} | {text}{reused} | {cell_text} | **{sc['mean']:.3f}**{mark} |{per_seed}"
                f" {sc['train_seconds']:.0f} |"
            )
    return lines, chosen, lowest


def main(argv=None) -> None:
    args = _arguments(argv)
    from furuta_gym.training.reproduce import machine_info

    furuta_gym.enable_x64()
    machine = machine_info()
    rows = _scores(args, *_train_candidates(args))
    first = next(iter(next(iter(rows.values())).values()))
    sets = list(first["sets"])
    names = list(first["sets"][sets[0]])
    table, chosen, lowest = _decide(args, rows, sets, names)
    lines = _header(args, machine, sets, names) + table
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.system}.md").write_text("\n".join(lines) + "\n")
    (args.out / f"{args.system}.json").write_text(
        json.dumps(
            {
                "system": args.system,
                "option": {args.where: args.name},
                "split": "validation",
                **({"quick": True} if args.quick else {}),
                "lower": lowest,
                "chosen": chosen,
                "scores": rows,
            },
            indent=1,
        )
        + "\n"
    )
    print("\n".join(lines))


if __name__ == "__main__":
    main()
