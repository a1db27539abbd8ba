"""The Furuta pendulum's simulated datasets (paper appendix "Data Generation"; the choices it
leaves open are the fields of :class:`FurutaRecipe`, described in :mod:`.datagen`)."""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

from ..signals import chirp, multisine, random_steps
from ._sampling import Clean, run_batch, run_each, stream, uniform
from ._system_data import SystemData

__all__ = ["FurutaRecipe", "FURUTA_DATA"]


@dataclasses.dataclass(frozen=True)
class FurutaRecipe:
    """The simulated Furuta datasets (paper appendix; see :mod:`.datagen` for choices)."""

    n_train: int = 64
    train_duration: float = 1.0
    angle_range: float = np.pi
    train_velocity_range: float = 5.0
    n_test_free: int = 6
    test_free_duration: float = 6.0
    test_velocity_range: float = 20.0
    n_test_forced: int = 3
    test_forced_duration: float = 20.0
    chirp_f0: float = 0.5
    chirp_f1: float = 6.0
    chirp_t1: float = 20.0  # the paper's "target time"
    amplitude: float = 2.0  # V
    n_scale_fit: int = 1
    scale_fit_duration: float = 20.0
    # "steps": random ±amplitude steps of its own; "chirp": the test chirp, as before the recipe
    # was frozen (a scale-fit trajectory then follows the forced test trajectories once both
    # forget their start)
    scale_fit_input: Literal["chirp", "steps"] = "steps"
    # validation (generate_validation): x0 in the training ranges, inputs other than the chirp;
    # free ones end before the pendulum settles (~3 s), where every free trajectory meets the others
    n_val_free: int = 12
    val_free_duration: float = 2.0
    n_val_forced: int = 3
    val_forced_duration: float = 20.0
    val_multisine_tones: int = 12
    val_scale_fit_duration: float = 20.0
    val_steps_hold: tuple[float, float] = (0.25, 1.0)

    @property
    def train_ranges(self) -> tuple[float, ...]:
        """±range of (α, β, α̇, β̇) of training, scale-fit and validation initial states."""
        return (self.angle_range, self.angle_range, self.train_velocity_range, self.train_velocity_range)

    @property
    def test_ranges(self) -> tuple[float, ...]:
        """±range of (α, β, α̇, β̇) of the test sets' initial states."""
        return (self.angle_range, self.angle_range, self.test_velocity_range, self.test_velocity_range)

    @classmethod
    def small(cls) -> "FurutaRecipe":
        """A scaled-down recipe for quick pipeline runs (16 train, 2 free + 1 forced short tests)."""
        return cls(
            n_train=16,
            n_test_free=2,
            test_free_duration=3.0,
            n_test_forced=1,
            test_forced_duration=10.0,
            scale_fit_duration=10.0,
            n_val_free=4,
            n_val_forced=1,
            val_forced_duration=10.0,
            val_scale_fit_duration=10.0,
        )


def _test_sets(r: FurutaRecipe, gt, seed, oversample) -> dict[str, list[Clean]]:
    train_ranges, test_ranges = r.train_ranges, r.test_ranges

    def u_chirp(t):
        return chirp(t, r.chirp_f0, r.chirp_f1, r.chirp_t1, r.amplitude)

    out = {}
    x0s = uniform(stream(seed, "train"), r.n_train, train_ranges)
    out["train"] = run_batch(
        gt, x0s, r.train_duration, np.zeros_like, oversample, [f"free{k:02d}" for k in range(r.n_train)]
    )
    x0s = uniform(stream(seed, "test_free"), r.n_test_free, test_ranges)
    out["test_free"] = run_batch(
        gt, x0s, r.test_free_duration, np.zeros_like, oversample, [f"free{k}" for k in range(r.n_test_free)]
    )
    x0s = uniform(stream(seed, "test_forced"), r.n_test_forced, test_ranges)
    out["test_forced"] = run_batch(
        gt, x0s, r.test_forced_duration, u_chirp, oversample, [f"chirp{k}" for k in range(r.n_test_forced)]
    )
    if r.scale_fit_input == "steps":
        out["scale_fit"] = run_each(
            gt,
            "scale_fit_input",
            seed,
            r.n_scale_fit,
            train_ranges,
            r.scale_fit_duration,
            lambda rng: lambda t: random_steps(t, r.val_steps_hold, r.amplitude, rng),
            oversample,
        )
        return out
    x0s = uniform(stream(seed, "scale_fit"), r.n_scale_fit, train_ranges)
    out["scale_fit"] = run_batch(
        gt, x0s, r.scale_fit_duration, u_chirp, oversample, [f"scale{k}" for k in range(r.n_scale_fit)]
    )
    return out


def _validation_sets(r: FurutaRecipe, gt, seed, oversample) -> dict[str, list[Clean]]:
    ranges = r.train_ranges
    free = uniform(stream(seed, "val_free"), r.n_val_free, ranges)
    out = {
        "val_free": run_batch(
            gt, free, r.val_free_duration, np.zeros_like, oversample, [f"free{k}" for k in range(r.n_val_free)]
        )
    }
    out["val_forced"] = run_each(
        gt,
        "val_forced",
        seed,
        r.n_val_forced,
        ranges,
        r.val_forced_duration,
        lambda rng: lambda t: multisine(t, r.chirp_f0, r.chirp_f1, r.val_multisine_tones, r.amplitude, rng),
        oversample,
    )
    out["val_scale_fit"] = run_each(
        gt,
        "val_scale_fit",
        seed,
        1,
        ranges,
        r.val_scale_fit_duration,
        lambda rng: lambda t: random_steps(t, r.val_steps_hold, r.amplitude, rng),
        oversample,
    )
    return out


FURUTA_DATA = SystemData(
    system="furuta",
    recipe=FurutaRecipe,
    test_names=("train", "test_free", "test_forced", "scale_fit"),
    validation_names=("val_free", "val_forced", "val_scale_fit"),
    make_test=_test_sets,
    make_validation=_validation_sets,
    test_labels={"Free": "test_free", "Forced": "test_forced"},
    validation_labels={"Free": "val_free", "Forced": "val_forced"},
    forced_set="test_forced",
    energy_set="test_free",
    state_labels=("α [rad]", "β [rad]", "α̇ [rad/s]", "β̇ [rad/s]"),
    main_claim="Furuta",
)
