"""What a reproduction run does (:class:`ReproduceSettings`), the sets it scores, and each run's
training settings from the recipe (:func:`training_settings`); part of :mod:`.reproduce`."""

from __future__ import annotations

import dataclasses
from typing import Any

from ..sensors import Sensors
from ..systems import get_spec
from ._labels import TEST_SETS
from .datagen import SYSTEM_DATA
from .loss_kinds import loss_kind
from .recipe import (
    DEFAULT_LEARNING_RATE,
    DEFAULT_QUADRATURE,
    QUICK_EPOCHS,
    QUICK_PROP_EPOCHS,
    RECIPE,
    SYSTEM_ROWS,
    RunRecipe,
    recipe_row,
)
from .train import TrainSettings

PAPER_PAIRS: tuple[tuple[str, str], ...] = (
    ("dln", "traj"),
    ("dln", "prop"),
    ("aph", "aph"),
    ("aph", "prop"),
    ("adln", "aph"),
    ("adln", "prop"),
)
#: What a selection run (``split="validation"``) is scored on instead: the validation datasets
#: (:func:`~furuta_gym.training.datagen.generate_validation`), which share no excitation with
#: the test sets; the Furuta scale is then fitted on ``val_scale_fit``, not ``scale_fit``.
VALIDATION_SETS = {name: dict(d.validation_labels) for name, d in SYSTEM_DATA.items()}
EVALUATION_SETS = {"test": TEST_SETS, "validation": VALIDATION_SETS}
SCALE_FIT_SET = {"test": "scale_fit", "validation": "val_scale_fit"}
PHYSICS_METRICS = ("inertial", "coriolis", "potential", "energy")
#: Columns of a system's metrics: each state variable's prediction error, then the physics terms.
METRIC_COLUMNS = {
    name: (*get_spec(name).joint_names, *(f"{j}_dot" for j in get_spec(name).joint_names), *PHYSICS_METRICS)
    for name in SYSTEM_DATA
}
#: How the data are measured (:attr:`ReproduceSettings.sensor`): the paper's simulated data, or as its
#: QUBE recordings were.
SENSORS = {"exact": Sensors(), "experiment": Sensors.qube()}
#: What the models train on (:attr:`ReproduceSettings.training_velocities`).
TRAINING_VELOCITIES = ("recorded", "zero_phase")
#: Where the models are trained (:attr:`ReproduceSettings.executor`).
EXECUTORS = ("local", "ray")
#: Table value of a model whose training failed (no finite model; reason in metrics.json).
FAILED = "fail"


@dataclasses.dataclass(frozen=True)
class ReproduceSettings:
    """What a reproduction run does.

    ``quick``: scaled-down datasets and far fewer epochs (minutes, not the paper's numbers);
    ``jobs``: models trained at once in separate processes (each model is mostly one core's
    work, so ``jobs`` = number of cores roughly divides the wall time by it);
    ``seeds``: model-initialisation seeds (the data come from ``data_seed``); ``systems`` /
    ``pairs``: subsets for tests; ``epochs``: override the per-system epoch schedule
    ``{system: (stage-1 epochs, stage-2 epochs)}`` of the L_traj / L_aph runs; ``prop_epochs``
    the same for L_prop, ``{system: (L_Iτ-alone epochs, stage 1, stage 2)}`` (a pair: no L_Iτ
    stage); ``small_data`` overrides the dataset size
    (default: small when quick); ``train_overrides``: extra :class:`TrainSettings` fields;
    ``model_overrides``: model hyper-parameters (:func:`~furuta_gym.models.make_model` keywords)
    for every model of the run, recorded with its settings like the defaults (a key a model kind
    does not know is an error, so runs that override F_a options name only aph / adln pairs).
    ``split``: ``"test"`` (the reproduction) or ``"validation"`` (a selection run: trained on the
    same training data, scale-fitted and scored on the validation datasets only — no test set
    is written or scored, no figure made).
    ``executor``: ``"local"`` (this process, or a local pool of ``jobs`` processes) or ``"ray"``
    (each model × seed a Ray task asking for ``cpus_per_task`` CPUs, on the cluster at
    ``address`` or, without one, on a local Ray instance running ``jobs`` tasks at once; needs
    the ``[cluster]`` extra). Neither changes a result: the run folders are the same.
    ``plant``: a plant file (a diagnosis JSON or an MJCF that furuta-gym wrote) whose MuJoCo
    plant generates the data instead of the shipped model, and whose model (its lumped parameters
    and memoryless effects) is the truth the physics columns compare with; the state columns then
    sit beside the paper's *experimental* values. ``sensor``: ``"exact"`` (the paper's simulated
    data) or ``"experiment"`` (its QUBE recordings: 2048-count encoders and the derivative filter
    ω0 = 100, ξ = 0.8 for the velocities, at 500 Hz). ``integral_span``: quadrature intervals
    summed into one L_Iτ residual in every L_prop run (1: the paper's; see
    :func:`~furuta_gym.training.losses.integral_loss_terms`, and docs/learning.md for its use on
    data whose velocities a filter estimated). ``training_velocities``: the training and
    scale-fit trajectories' velocities as the sensor gave them (``"recorded"``) or re-estimated
    offline from the angles without lag (``"zero_phase"``,
    :func:`~furuta_gym.signals.zero_phase_velocity`), as one would process logged data; the test
    sets are scored as recorded either way.
    """

    quick: bool = False
    seeds: tuple[int, ...] = (0,)
    data_seed: int = 0
    systems: tuple[str, ...] = ("nmsd", "furuta")
    pairs: tuple[tuple[str, str], ...] = PAPER_PAIRS
    epochs: dict | None = None
    prop_epochs: dict | None = None
    small_data: bool | None = None
    train_overrides: dict | None = None
    model_overrides: dict | None = None
    ground_truth: str = "auto"
    plant: str | None = None
    sensor: str = "exact"
    figures: bool = True
    progress: bool = True
    jobs: int = 1
    split: str = "test"
    executor: str = "local"
    address: str | None = None
    cpus_per_task: int = 1
    integral_span: int = 1
    training_velocities: str = "recorded"

    def __post_init__(self):
        self._check_execution()
        self._check_runs()
        self._check_data()

    def _check_execution(self) -> None:
        """What is evaluated, and how the runs are spread over processes or a cluster."""
        if self.split not in EVALUATION_SETS:
            raise ValueError(f"split must be one of {sorted(EVALUATION_SETS)}, got {self.split!r}")
        if int(self.jobs) < 1:
            raise ValueError(f"jobs must be at least 1, got {self.jobs}")
        if self.executor not in EXECUTORS:
            raise ValueError(f"executor must be one of {EXECUTORS}, got {self.executor!r}")
        if self.address is not None and self.executor != "ray":
            raise ValueError("address names a Ray cluster: it needs executor='ray'")
        if int(self.cpus_per_task) < 1:
            raise ValueError(f"cpus_per_task must be at least 1, got {self.cpus_per_task}")

    def _check_runs(self) -> None:
        """The systems, (model, loss) pairs and seeds, each run once."""
        for s in self.systems:
            get_spec(s)
        for kind, loss in self.pairs:
            if (kind, loss) not in PAPER_PAIRS:
                raise ValueError(f"pair ({kind!r}, {loss!r}) is not one the paper reports: {PAPER_PAIRS}")
        if not self.seeds:
            raise ValueError("seeds must name at least one seed")
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds must differ: a seed twice would count one model twice, got {self.seeds}")

    def _check_data(self) -> None:
        """How the training data are made and read."""
        if not (isinstance(self.integral_span, int) and self.integral_span >= 1):
            raise ValueError(
                f"integral_span must be a positive integer (intervals per L_Iτ residual), got {self.integral_span!r}"
            )
        if self.training_velocities not in TRAINING_VELOCITIES:
            raise ValueError(
                f"training_velocities must be one of {TRAINING_VELOCITIES}, got {self.training_velocities!r}"
            )
        if self.sensor not in SENSORS:
            raise ValueError(f"sensor must be one of {sorted(SENSORS)}, got {self.sensor!r}")
        if self.plant is not None and self.ground_truth == "analytic":
            raise ValueError("plant= is a MuJoCo plant: it needs ground_truth 'auto' or 'mujoco'")

    @property
    def small(self) -> bool:
        return self.quick if self.small_data is None else self.small_data


# The full run's recipe is one table (:mod:`furuta_gym.training.recipe`, rows citing the decision
# log in docs/reproduce.md); the names below are views of it.
FULL_PROP_EPOCHS = {s: rows["prop"].epochs for s, rows in SYSTEM_ROWS.items()}
REPRODUCE_QUADRATURE = DEFAULT_QUADRATURE
_PROP_ROWS = {(s, k): row for (s, k, loss), row in RECIPE.items() if loss_kind(loss).proposed}
FULL_PROP_QUADRATURE = {key: row.quadrature for key, row in _PROP_ROWS.items() if row.quadrature != DEFAULT_QUADRATURE}
FULL_PROP_FINETUNE_LEARNING_RATE = {
    key: row.finetune_learning_rate
    for key, row in _PROP_ROWS.items()
    if row.finetune_learning_rate != DEFAULT_LEARNING_RATE
}


def _run_recipe(system: str, config: ReproduceSettings, loss: str, kind: str | None) -> RunRecipe:
    """The recipe row of one run: the full run's, or with ``--quick``'s / the caller's epochs."""
    name = get_spec(system).name
    if not loss_kind(loss).proposed:
        table = config.epochs or (QUICK_EPOCHS if config.quick else None)
    else:
        table = config.prop_epochs or (QUICK_PROP_EPOCHS if config.quick else None)
    return recipe_row(name, kind, loss, None if table is None else tuple(table[name]))


def epoch_schedule(system: str, config: ReproduceSettings, loss: str, kind: str | None = None) -> tuple[int, ...]:
    """Epochs per stage of ``loss`` runs of model ``kind`` on ``system`` (L_prop: ``(L_Iτ alone,
    stage 1, stage 2)``, others ``(stage 1, stage 2)``)."""
    return _run_recipe(system, config, loss, kind).epochs


def quadrature_rule(system: str, config: ReproduceSettings, loss: str, kind: str | None = None) -> str:
    """L_Iτ's quadrature (and, on the Furuta, the scale fit's) for ``loss`` runs of ``kind`` on
    ``system``, before the caller's overrides."""
    return _run_recipe(system, config, loss, kind).quadrature


def training_settings(system: str, config: ReproduceSettings, seed: int, loss: str = "prop", kind: str | None = None):
    """The :class:`~furuta_gym.training.TrainSettings` of one run of model ``kind`` on ``system``
    with ``loss``: its recipe row, then the caller's ``train_overrides``."""
    name = get_spec(system).name
    row = _run_recipe(name, config, loss, kind)
    horizons = tuple(TrainSettings.for_system(name).horizons)
    proposed = loss_kind(loss).proposed
    if proposed and len(row.epochs) == 3:  # a leading stage of L_Iτ alone
        horizons = (None, *horizons)
    overrides: dict[str, Any] = dict(
        epochs=row.epochs,
        horizons=horizons,
        seed=seed,
        progress=config.progress,
        checkpoint_every=0,
        quadrature=row.quadrature,
    )
    if config.quick:  # a few hundred steps per model: compiling them is most of the run
        overrides["fast_compile"] = True
    if proposed:
        overrides["lambda_traj"] = row.lambda_traj
        overrides["integral_span"] = config.integral_span
        if row.augmentation_weight is not None:
            # written out, not left to the None default: the run record then says which μ it used
            overrides["augmentation_weight"] = row.augmentation_weight
        steps = (row.itau_learning_rate, row.finetune_learning_rate)
        if len(row.epochs) == 3 and steps != (TrainSettings.learning_rate,) * 2:
            overrides["learning_rate"] = (steps[0], steps[1], steps[1])
    overrides.update(config.train_overrides or {})
    return TrainSettings.for_system(name, **overrides)
