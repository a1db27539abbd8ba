"""The nonlinear mass-spring-damper's simulated datasets (paper appendix "Data Generation"; the
choices it leaves open are the fields of :class:`NMSDRecipe`, described in :mod:`.datagen`)."""

from __future__ import annotations

import dataclasses

from ..signals import chirp, multisine, random_steps, square_pulse
from ._sampling import DATA_RATE_HZ, Clean, run_batch, run_each, stream, uniform
from ._system_data import SystemData

__all__ = ["NMSDRecipe", "NMSD_DATA"]


@dataclasses.dataclass(frozen=True)
class NMSDRecipe:
    """The N-MSD datasets (paper appendix; amplitude and test counts are our choice)."""

    train_duration: float = 60.0
    segment_duration: float = 2.0
    chirp_f0: float = 0.1
    chirp_f1: float = 1.1
    amplitude: float = 5.0  # N, chirp and pulse
    p0_range: float = 1.0
    pd0_range: float = 5.0
    n_test_chirp: int = 3
    test_chirp_duration: float = 25.0
    n_test_square: int = 3
    test_square_duration: float = 15.0
    pulse_start: float = 1.0
    pulse_width: float = 3.0
    # validation (generate_validation): x0 inside the training trajectory's range
    val_p0_range: float = 0.5
    val_pd0_range: float = 2.5
    n_val_multisine: int = 3
    val_multisine_duration: float = 25.0
    val_multisine_tones: int = 8
    n_val_steps: int = 3
    val_steps_duration: float = 15.0
    val_steps_hold: tuple[float, float] = (1.0, 3.0)

    @classmethod
    def small(cls) -> "NMSDRecipe":
        """A scaled-down recipe for quick pipeline runs (10 segments, 1 + 1 short tests)."""
        return cls(
            train_duration=20.0,
            n_test_chirp=1,
            test_chirp_duration=10.0,
            n_test_square=1,
            test_square_duration=10.0,
            n_val_multisine=1,
            val_multisine_duration=10.0,
            n_val_steps=1,
            val_steps_duration=10.0,
        )


def _segments(long: Clean, r: NMSDRecipe, oversample: int) -> list[Clean]:
    """The long training trajectory cut into segments (adjacent ones share a boundary sample)."""
    n_seg = int(round(r.train_duration / r.segment_duration))
    seg_len = int(round(r.segment_duration * DATA_RATE_HZ)) * oversample
    return [
        Clean(
            t=long.t[k * seg_len : (k + 1) * seg_len + 1] - long.t[k * seg_len],
            x=long.x[k * seg_len : (k + 1) * seg_len + 1],
            u=long.u[k * seg_len : (k + 1) * seg_len + 1],
            name=f"seg{k:02d}",
        )
        for k in range(n_seg)
    ]


def _test_sets(r: NMSDRecipe, gt, seed, oversample) -> dict[str, list[Clean]]:
    ranges = (r.p0_range, r.pd0_range)
    x0 = uniform(stream(seed, "train"), 1, ranges)
    (long,) = run_batch(
        gt,
        x0,
        r.train_duration,
        lambda t: chirp(t, r.chirp_f0, r.chirp_f1, r.train_duration, r.amplitude),
        oversample,
        ["train"],
    )
    out = {"train": _segments(long, r, oversample)}
    x0s = uniform(stream(seed, "test_chirp"), r.n_test_chirp, ranges)
    out["test_chirp"] = run_batch(
        gt,
        x0s,
        r.test_chirp_duration,
        lambda t: chirp(t, r.chirp_f0, r.chirp_f1, r.test_chirp_duration, r.amplitude),
        oversample,
        [f"chirp{k}" for k in range(r.n_test_chirp)],
    )
    x0s = uniform(stream(seed, "test_square"), r.n_test_square, ranges)
    out["test_square"] = run_batch(
        gt,
        x0s,
        r.test_square_duration,
        lambda t: square_pulse(t, r.pulse_start, r.pulse_width, r.amplitude),
        oversample,
        [f"square{k}" for k in range(r.n_test_square)],
    )
    return out


def _validation_sets(r: NMSDRecipe, gt, seed, oversample) -> dict[str, list[Clean]]:
    ranges = (r.val_p0_range, r.val_pd0_range)
    out = {}
    for name, n, duration, make_u in (
        (
            "val_multisine",
            r.n_val_multisine,
            r.val_multisine_duration,
            lambda rng: lambda t: multisine(t, r.chirp_f0, r.chirp_f1, r.val_multisine_tones, r.amplitude, rng),
        ),
        (
            "val_steps",
            r.n_val_steps,
            r.val_steps_duration,
            lambda rng: lambda t: random_steps(t, r.val_steps_hold, r.amplitude, rng),
        ),
    ):
        out[name] = run_each(gt, name, seed, n, ranges, duration, make_u, oversample)
    return out


NMSD_DATA = SystemData(
    system="nmsd",
    recipe=NMSDRecipe,
    test_names=("train", "test_chirp", "test_square"),
    validation_names=("val_multisine", "val_steps"),
    make_test=_test_sets,
    make_validation=_validation_sets,
    test_labels={"Chirp": "test_chirp", "Square": "test_square"},
    validation_labels={"Multisine": "val_multisine", "Steps": "val_steps"},
    forced_set="test_square",
    energy_set="test_chirp",
    state_labels=("p [m]", "ṗ [m/s]"),
)
