"""The rule studies/select_option.py applies to choose a recipe option over several model seeds."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
from select_option import choose  # noqa: E402


def test_a_value_replaces_the_recipes_only_if_every_seed_prefers_it():
    # the Furuta DeLaN's quadrature (results/quadrature_seeds): Hermite's mean is lower, seed 0 is not
    chosen, paired = choose({"simpson": [-1.242, -0.961, -0.888], "hermite": [-1.166, -1.094, -0.993]})
    assert chosen == "simpson"
    assert paired["hermite"]["every_seed"] is False
    assert paired["hermite"]["differences"] == pytest.approx([0.076, -0.133, -0.105])
    # augmented DeLaN's (results/quadrature_adln_seeds): lower on every seed
    chosen, paired = choose({"simpson": [-1.139, -1.068, -1.226], "hermite": [-1.178, -1.508, -1.475]})
    assert chosen == "hermite" and paired["hermite"]["every_seed"]


def test_among_values_better_on_every_seed_the_lowest_mean_wins_and_ties_keep_the_recipe():
    means = {"a": [0.0, 0.0, 0.0], "b": [-0.1, -0.1, -0.1], "c": [-0.5, -0.01, -0.5], "d": [-2.0, 0.1, -2.0]}
    assert choose(means)[0] == "c"  # d has the lowest mean but is worse on seed 1
    assert choose({"a": [0.0, 0.0], "b": [0.0, -1.0]})[0] == "a"  # equal on a seed is not better
    # one seed: the plain lowest mean
    assert choose({"a": [0.0], "b": [-0.1]}) == ("b", {})
    with pytest.raises(ValueError, match="'b' has 3 seed means"):
        choose({"a": [0.0, 0.0], "b": [0.0, -1.0, -1.0]})


def test_a_value_beaten_on_a_seed_may_stop_there_and_is_never_chosen():
    # beaten on seed 0 (equal counts as beaten), or on seed 1 after winning seed 0
    chosen, paired = choose({"a": [0.0, 0.0, 0.0], "b": [0.0], "c": [-0.2, 0.1], "d": [-0.1, -0.1, -0.1]})
    assert chosen == "d"
    assert paired["b"] == {"differences": [0.0], "every_seed": False}
    assert paired["c"]["differences"] == pytest.approx([-0.2, 0.1]) and not paired["c"]["every_seed"]
    # every value beaten on seed 0: the recipe's value has one seed too, and the paired rule
    # (asked for several seeds) still reports the differences
    chosen, paired = choose({"a": [0.0], "b": [0.3]}, several_seeds=True)
    assert chosen == "a" and paired["b"] == {"differences": [0.3], "every_seed": False}
    # stopping while ahead is not the rule
    with pytest.raises(ValueError, match="not beaten on its last seed"):
        choose({"a": [0.0, 0.0, 0.0], "b": [-0.1]})


def test_seeds_are_trained_in_turn_and_a_beaten_value_is_not_trained_again():
    from select_option import _train_in_turn

    means = {"a": [0.0, 0.0, 0.0], "b": [0.1, -9.0, -9.0], "c": [-0.1, 0.2, -9.0], "d": [-0.1, -0.1, -0.1]}
    calls = []
    trained = _train_in_turn(
        "a",
        [("adln", v, f"out/{v}") for v in means],
        (0, 1, 2),
        lambda live, seed: calls.append((seed, [t for _, t, _ in live])),
        lambda kind, out, seed: means[out.split("/")[1]][seed],
    )
    assert calls == [(0, ["a", "b", "c", "d"]), (1, ["a", "c", "d"]), (2, ["a", "d"])]
    assert trained == {("adln", "a"): [0, 1, 2], ("adln", "b"): [0], ("adln", "c"): [0, 1], ("adln", "d"): [0, 1, 2]}
    # all beaten on seed 0: nothing more is trained
    calls.clear()
    trained = _train_in_turn(
        "a",
        [("adln", "a", "out/a"), ("adln", "b", "out/b")],
        (0, 1, 2),
        lambda live, seed: calls.append(seed),
        lambda kind, out, seed: means[out[4:]][seed],
    )
    assert calls == [0] and trained == {("adln", "a"): [0], ("adln", "b"): [0]}


def test_selection_candidates_are_validation_runs():
    """Both selection scripts train their candidates as validation runs: scale fitted on
    val_scale_fit, scored on the validation sets, no test set generated (tests/test_reproduce.py
    checks what a validation run does)."""
    import select_augmentation_weight
    import select_option

    config = select_option._config("furuta", "adln", "train", "quadrature", "hermite", seeds=3)
    assert config.split == "validation" and config.seeds == (0, 1, 2) and not config.figures
    config = select_augmentation_weight._config("nmsd", "adln", 0.1)
    assert config.split == "validation" and config.train_overrides == {"augmentation_weight": 0.1}


def test_the_candidates_train_where_executor_says_and_ray_without_ray_is_one_error(tmp_path, monkeypatch):
    """--executor / --address / --cpus-per-task as `furuta-gym reproduce` takes them; the local pool
    stays the default; without Ray installed, --executor ray stops before any work with the
    package's one line naming the extra (tests/test_cluster.py runs the script on Ray)."""
    import select_option

    argv = ["--system", "nmsd", "--kinds", "dln", "--train", "epochs", "[1,0,0]", "[2,0,0]", "--out", str(tmp_path)]
    workers = select_option._arguments(argv).workers
    assert (workers.executor, workers.address, workers.jobs, workers.cpus_per_task) == ("local", None, 2, 1)
    workers = select_option._arguments(
        [*argv, "--executor", "ray", "--address", "auto", "--cpus-per-task", "2"]
    ).workers
    assert (workers.executor, workers.address, workers.cpus_per_task) == ("ray", "auto", 2)
    with pytest.raises(SystemExit):  # argparse's error: address names a Ray cluster: it needs executor='ray'
        select_option._arguments([*argv, "--address", "auto"])
    monkeypatch.setitem(sys.modules, "ray", None)  # as without the [cluster] extra
    with pytest.raises(SystemExit, match=r"error: --executor ray needs Ray: pip install 'furuta-gym\[cluster\]'$"):
        select_option.main([*argv, "--executor", "ray"])
    assert list(tmp_path.iterdir()) == []
