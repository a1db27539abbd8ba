"""L_Iτ normalised per joint (issue 44): each joint's squared residual over its own momentum changes.

On the calibrated rig's free releases the rotor's momentum hardly changes while its equation holds
forces a DeLaN cannot express (a cable spring, dry friction); normalised by the momentum changes of
both joints together, the loss can shrink the rotor's row of M and its damping to weigh that
equation less. Per joint it cannot, and it stays free of the overall scale (free data leave it open).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import furuta_gym
from furuta_gym.cli import build_parser
from furuta_gym.cli.reproduce import config_from_args
from furuta_gym.diagnose._library import nominal_base
from furuta_gym.effects import Effect
from furuta_gym.models import NMSD, LumpedSystem
from furuta_gym.rigs import measured_like
from furuta_gym.training.losses import _integral_parts, integral_loss, make_windows
from furuta_gym.training.train import TrainSettings

furuta_gym.enable_x64()
RIG = [Effect("spring", "alpha", 2e-3), Effect("coulomb_friction", "alpha", 5e-4)]


@pytest.fixture(scope="module")
def releases():
    """Free releases of a rotor with a cable spring and dry friction (exact states)."""
    data = measured_like(
        "furuta", RIG, forced=False, n_trajectories=6, duration=1.0, seed=0, quantize=False, true_velocities=True
    )
    return make_windows(data, 51, stride=50, cover_end=True)


def test_each_joint_is_normalised_by_its_own_momentum_changes_and_the_overall_scale_is_free(releases):
    model = LumpedSystem.of("furuta", nominal_base("furuta"))  # the rig without its spring and friction
    r, dp, _, _ = _integral_parts(model, releases, "simpson", span=2)
    per_joint = jnp.sum(r**2, axis=(0, 1)) / jnp.sum(dp**2, axis=(0, 1))
    joint = integral_loss(model, releases, rule="simpson", normalize="joint_momentum", span=2)
    together = integral_loss(model, releases, rule="simpson", normalize="momentum", span=2)
    assert float(joint) == pytest.approx(float(jnp.sum(per_joint)), rel=1e-12)
    assert float(joint) != pytest.approx(float(together), rel=0.1)
    tripled = LumpedSystem.of("furuta", {k: 3 * v for k, v in nominal_base("furuta").items()})
    assert float(integral_loss(tripled, releases, rule="simpson", normalize="joint_momentum", span=2)) == pytest.approx(
        float(joint), rel=1e-10
    )


def test_with_one_joint_it_is_the_momentum_normalisation():
    t = np.arange(0.0, 2.0, 0.01)
    x = np.stack([np.cos(3 * t), -3 * np.sin(3 * t)], 1)
    traj = furuta_gym.data.Trajectory(t, x[:, :1], np.zeros((t.size, 1)), x[:, 1:])
    windows = make_windows([traj], 21, stride=20, cover_end=True)
    a, b = (float(integral_loss(NMSD(), windows, normalize=n)) for n in ("joint_momentum", "momentum"))
    assert a == pytest.approx(b, rel=1e-12) and a > 0


def test_the_normalisation_is_named_on_the_command_line_and_checked():
    _, config = config_from_args(build_parser().parse_args(["reproduce", "--itau-normalization", "joint_momentum"]))
    assert config.train_overrides == {"normalize": "joint_momentum"}
    _, default = config_from_args(build_parser().parse_args(["reproduce"]))
    assert default.train_overrides is None
    with pytest.raises(ValueError, match="normalize must be one of .*joint_momentum"):
        TrainSettings(normalize="per_joint")  # type: ignore[arg-type]
