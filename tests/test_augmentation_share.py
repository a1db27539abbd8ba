"""L_prop's minimum-norm term for models with a data-driven force F_a (APHYNITY, augmented DeLaN):
P_a = Σ‖∫M̂⁻¹F_a dt‖² / Σ‖Δq̇‖², weighted by μ = ``TrainSettings.augmentation_weight``."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from _simulated import nmsd_chirp_segments
from furuta_gym.lagrangian import interval_difference, interval_integral
from furuta_gym.models import make_model
from furuta_gym.training.losses import integral_loss, integral_loss_terms, make_windows, proposed_loss
from furuta_gym.training.train import TrainSettings, train


@pytest.fixture(scope="module")
def segments():
    return nmsd_chirp_segments(3.0)


def test_share_is_the_augmentation_velocity_change_relative_to_the_data_and_scale_free(segments):
    model = make_model("nmsd", "aph", jax.random.PRNGKey(3))
    w = make_windows(segments, 21, stride=20)
    itau, share = integral_loss_terms(model, w, rule="simpson", normalize="momentum", with_augmentation=True)
    num = den = 0.0
    for t, x in zip(np.asarray(w.t), np.asarray(w.x), strict=True):
        q, qd = jnp.asarray(x[:, :1]), jnp.asarray(x[:, 1:])
        acc = jax.vmap(lambda a, b: jnp.linalg.solve(model.mass_matrix(a), model.augmentation(a, b)))(q, qd)
        num += float(jnp.sum(interval_integral(acc, t[1] - t[0], "simpson") ** 2))
        den += float(jnp.sum(interval_difference(qd, "simpson") ** 2))
    assert float(share) == pytest.approx(num / den, rel=1e-10)
    assert float(itau) == pytest.approx(float(integral_loss(model, w, rule="simpson", normalize="momentum")), rel=1e-12)
    # like L_Iτ on free data, the share cannot be lowered by shrinking the whole model
    _, share3 = integral_loss_terms(
        model.with_scale(3.0), w, rule="simpson", normalize="momentum", with_augmentation=True
    )
    assert float(share3) == pytest.approx(float(share), rel=1e-10)
    # proposed_loss adds μ·P_a on top of L_Iτ + λ·L_traj
    short = make_windows(segments[:2], 3, stride=10)
    base = float(proposed_loss(model, w, short, 0.5, rule="simpson", normalize="momentum"))
    with_mu = float(proposed_loss(model, w, short, 0.5, rule="simpson", normalize="momentum", augmentation_weight=0.01))
    assert with_mu - base == pytest.approx(0.01 * float(share), rel=1e-9)


def test_share_with_the_hermite_rule_integrates_at_its_interior_nodes(segments):
    """P_a and L_Iτ go through the same quadrature: with "hermite" both integrate on the
    interpolated states between samples, over the paper's per-sample intervals."""
    model = make_model("nmsd", "aph", jax.random.PRNGKey(3))
    w = make_windows(segments, 21, stride=20)
    _, share = integral_loss_terms(model, w, rule="hermite", normalize="momentum", with_augmentation=True)
    num = den = 0.0
    g = 0.5 / np.sqrt(3.0)
    for t, x in zip(np.asarray(w.t), np.asarray(w.x), strict=True):
        q, qd, dt = x[:, :1], x[:, 1:], t[1] - t[0]
        total = 0.0
        for s in (0.5 - g, 0.5 + g):  # the cubic through (q, q̇) at both ends, written out here
            qs = (
                (2 * s**3 - 3 * s**2 + 1) * q[:-1]
                + (-2 * s**3 + 3 * s**2) * q[1:]
                + dt * ((s**3 - 2 * s**2 + s) * qd[:-1] + (s**3 - s**2) * qd[1:])
            )
            vs = (
                (6 * s**2 - 6 * s) * (q[:-1] - q[1:]) / dt
                + (3 * s**2 - 4 * s + 1) * qd[:-1]
                + (3 * s**2 - 2 * s) * qd[1:]
            )
            acc = jax.vmap(lambda a, b: jnp.linalg.solve(model.mass_matrix(a), model.augmentation(a, b)))(
                jnp.asarray(qs), jnp.asarray(vs)
            )
            total = total + 0.5 * dt * np.asarray(acc)
        num += float(np.sum(total**2))
        den += float(np.sum((qd[1:] - qd[:-1]) ** 2))
    assert float(share) == pytest.approx(num / den, rel=1e-10)
    # the match above tells the rules apart: Simpson's value on the same data is 1e6× further off
    _, simpson = integral_loss_terms(model, w, rule="simpson", normalize="momentum", with_augmentation=True)
    assert abs(float(share) / float(simpson) - 1) > 1e-4


def test_weight_on_a_model_without_augmentation_or_negative_is_refused(segments):
    with pytest.raises(ValueError, match="augmentation_weight must be non-negative"):
        TrainSettings(augmentation_weight=-1.0)
    cfg = TrainSettings.for_system("nmsd", epochs=(1,), horizons=(None,), augmentation_weight=1e-3, progress=False)
    with pytest.raises(ValueError, match="augmentation_weight=0.001.*'dln'.*only aph and adln"):
        train("dln", "nmsd", "prop", segments, cfg)


def test_the_weight_moves_a_spring_force_out_of_the_network_into_the_prior(segments):
    """L_Iτ alone is indifferent to whether the spring force sits in the prior (k1) or in F_a(p):
    started from a prior whose k1 is 30 % low, μ·P_a makes the prior take it back."""
    cfg = dict(
        epochs=(300,), horizons=(None,), quadrature="simpson", learning_rate=1e-2, progress=False, checkpoint_every=0
    )
    hp = dict(prior=(("k1", 7.0),))
    runs = {}
    for mu in (0.0, 0.1):
        model, history = train(
            "aph", "nmsd", "prop", segments, TrainSettings.for_system("nmsd", augmentation_weight=mu, **cfg), hparams=hp
        )
        k1 = float(model.physical_parameters["k1"])
        runs[mu] = (k1, history[-1])
    (k1_free, h_free), (k1_mu, h_mu) = runs[0.0], runs[0.1]
    assert "fa_share" not in h_free and h_mu["fa_share"] > 0
    assert h_mu["total"] == pytest.approx(h_mu["itau"] + 0.1 * h_mu["fa_share"], rel=1e-12)
    # with μ the prior's spring is much closer to the true k1 = 10 (measured: 9.6 against 7.8)
    assert abs(k1_mu - 10.0) < 0.5 * abs(k1_free - 10.0)


def test_force_network_linear_velocity_term_and_activation():
    """F_a = force_scale·net(x) + damping_scale·W·q̇: W starts at zero (the initial F_a is the
    network's), carries a linear velocity dependence that does not saturate, and can be dropped.
    W = 1 is a damping of the system's physical order (1e-3 N·m·s/rad for the Furuta). By default
    W is per joint (diagonal: each joint's friction from its own velocity); a full matrix and no
    W are options."""
    import equinox as eqx

    model = make_model("furuta", "aph", 0)
    net = model.force_net
    assert net.linear.shape == (2,) and not np.any(np.asarray(net.linear))
    assert dict(model.hparams)["linear_velocity"] == "diagonal"
    assert make_model("furuta", "adln", 0).force_net.linear.shape == (2,)
    # the network's activation is chosen per system and model kind (the system's definition)
    assert net.net.activation == "tanh" and dict(model.hparams)["force_activation"] == "tanh"
    assert make_model("furuta", "adln", 0).force_net.net.activation == "silu"
    assert make_model("nmsd", "aph", 0).force_net.net.activation == "silu"
    q = jnp.array([0.3, 1.0])
    w = jnp.array([-2.0, -0.5])
    linear_only = eqx.tree_at(lambda m: m.force_net.linear, model, w)
    full = make_model("furuta", "aph", 0, linear_velocity=True)
    assert full.force_net.linear.shape == (2, 2)
    W = jnp.array([[-2.0, 0.3], [0.1, -0.5]])
    full_only = eqx.tree_at(lambda m: m.force_net.linear, full, W)
    for qd in (jnp.array([1.0, -2.0]), jnp.array([100.0, 40.0])):
        diff = linear_only.augmentation(q, qd) - model.augmentation(q, qd)
        np.testing.assert_allclose(diff, 1e-3 * w * qd, rtol=1e-12)
        diff = full_only.augmentation(q, qd) - full.augmentation(q, qd)
        np.testing.assert_allclose(diff, 1e-3 * W @ qd, rtol=1e-12)
    assert net.damping_scale == 1e-3  # the unit is chosen per system and model kind
    assert make_model("nmsd", "adln", 0).force_net.damping_scale == 0.2
    assert make_model("nmsd", "aph", 0).force_net.damping_scale == 0.2
    plain = make_model("furuta", "adln", 0, linear_velocity=False, force_activation="tanh")
    assert plain.force_net.linear is None and plain.force_net.net.activation == "tanh"
    with pytest.raises(ValueError, match="linear_velocity must be True, False or 'diagonal'"):
        make_model("furuta", "adln", 0, linear_velocity="upper")
    # the Lagrangian networks keep their own activation
    assert plain.lagrangian_nets.mass_net.activation == "tanh"


@pytest.mark.parametrize("system, kind", [("nmsd", "adln"), ("furuta", "aph")])
def test_force_network_odd_in_velocity_holds_no_force_at_rest(system, kind):
    """odd_in_velocity: F_a(q, −q̇) = −F_a(q, q̇), so nothing even in q̇ (a spring, gravity, a
    constant torque) can sit in F_a. A general F_a has a force at rest."""
    odd = make_model(system, kind, jax.random.PRNGKey(4), odd_in_velocity=True)
    general = make_model(system, kind, jax.random.PRNGKey(4), odd_in_velocity=False)
    n = odd.spec.n_dof
    rng = np.random.default_rng(0)
    for _ in range(5):
        q, qd = jnp.asarray(rng.uniform(-2, 2, n)), jnp.asarray(rng.uniform(-8, 8, n))
        np.testing.assert_allclose(odd.augmentation(q, -qd), -odd.augmentation(q, qd), rtol=0, atol=1e-18)
        assert float(jnp.max(jnp.abs(odd.augmentation(q, jnp.zeros(n))))) == 0.0
        assert float(jnp.max(jnp.abs(general.augmentation(q, jnp.zeros(n))))) > 0.0
    with pytest.raises(ValueError, match="odd_in_velocity must be True or False"):
        make_model(system, kind, 0, odd_in_velocity="yes")


def test_only_augmented_delan_on_the_nmsd_has_an_odd_force_by_default():
    """The per-system choice made on validation data (models/_augmented.py, FORCE_DEFAULTS)."""
    defaults = {
        (s, k): dict(make_model(s, k, 0).hparams)["odd_in_velocity"]
        for s in ("nmsd", "furuta")
        for k in ("aph", "adln")
    }
    assert defaults == {
        ("nmsd", "aph"): False,
        ("nmsd", "adln"): True,
        ("furuta", "aph"): False,
        ("furuta", "adln"): False,
    }
    assert make_model("nmsd", "adln", 0).force_net.odd_in_velocity is True


def test_checkpoints_from_before_the_force_network_choices_load_as_trained(tmp_path):
    """A checkpoint whose header predates prior_back_emf / linear_velocity / force_activation
    rebuilds the architecture it was trained with (back-EMF in the prior, no W, tanh)."""
    import json

    from furuta_gym.models import checkpoint as ckpt

    old = make_model(
        "furuta", "aph", jax.random.PRNGKey(2), prior_back_emf=True, linear_velocity=False, force_activation="tanh"
    )
    path = ckpt.save_model(tmp_path / "old.eqx", old)
    header, payload = ckpt._read(path)
    for key in ("prior_back_emf", "linear_velocity", "force_activation", "odd_in_velocity"):
        del header["hparams"][key]
    del header["format"]  # a form-1 header: written before the format was recorded
    ckpt._write(path, {k: v for k, v in header.items() if not k.startswith("payload")}, old, overwrite=True)
    assert "linear_velocity" not in json.dumps(ckpt.read_header(path)["hparams"])
    loaded = ckpt.load_model(path)
    q, qd, u = jnp.array([0.3, 1.0]), jnp.array([4.0, -2.0]), jnp.array([1.5])
    np.testing.assert_array_equal(loaded.augmentation(q, qd), old.augmentation(q, qd))
    assert loaded.force_net.odd_in_velocity is False
    np.testing.assert_array_equal(loaded.input_force(q, qd, u), old.input_force(q, qd, u))


def test_a_form_2_header_is_read_as_written_and_an_unknown_form_is_refused(tmp_path):
    """A current header records every hyper-parameter: nothing is filled in for it (a form-2
    header without ``odd_in_velocity`` builds today's default, not form 1's), and a header of a
    form this version does not know is one clear error naming the file."""
    from furuta_gym.models import checkpoint as ckpt

    model = make_model("nmsd", "adln", jax.random.PRNGKey(3))
    assert model.force_net.odd_in_velocity is True  # the N-MSD's default; form 1 would say False
    path = ckpt.save_model(tmp_path / "now.eqx", model)
    header, _ = ckpt._read(path)
    assert header["format"] == ckpt.HEADER_FORMAT == 2
    del header["hparams"]["odd_in_velocity"]
    ckpt._write(path, {k: v for k, v in header.items() if not k.startswith("payload")}, model, overwrite=True)
    assert ckpt.load_model(path).force_net.odd_in_velocity is True
    ckpt._write(
        path, {**{k: v for k, v in header.items() if not k.startswith("payload")}, "format": 3}, model, overwrite=True
    )
    with pytest.raises(ckpt.CheckpointError, match=r"now\.eqx.*format 3"):
        ckpt.load_model(path)


def test_checkpoints_from_before_damping_scale_keep_their_units_for_w(tmp_path):
    """Saved before W had its own physical scale, a model's W was in force_scale / velocity_scale
    units: it must load with that scale, or its damping would change by 10x."""
    import equinox as eqx

    from furuta_gym.models import checkpoint as ckpt

    # models of that time had the full matrix W (per-joint W came later)
    old = make_model("furuta", "adln", jax.random.PRNGKey(2), damping_scale=1e-3 / 10.0, linear_velocity=True)
    old = eqx.tree_at(lambda m: m.force_net.linear, old, jnp.array([[-5.0, 0.1], [0.2, -1.5]]))
    path = ckpt.save_model(tmp_path / "old.eqx", old)
    header, _ = ckpt._read(path)
    del header["hparams"]["damping_scale"]
    del header["format"]
    ckpt._write(path, {k: v for k, v in header.items() if not k.startswith("payload")}, old, overwrite=True)
    loaded = ckpt.load_model(path)
    assert loaded.force_net.damping_scale == pytest.approx(1e-4)
    q, qd = jnp.array([0.3, 1.0]), jnp.array([20.0, -7.0])
    np.testing.assert_array_equal(loaded.augmentation(q, qd), old.augmentation(q, qd))


def test_default_weight_is_on_for_both_augmented_kinds_and_zero_turns_it_off(segments):
    """μ = None takes AUGMENTATION_WEIGHT of the system and model kind (chosen on validation data,
    measured beyond the viscous term; train.py); μ = 0 leaves L_prop = L_Iτ + λ·L_traj."""
    from furuta_gym.training.train import AUGMENTATION_WEIGHT

    assert set(AUGMENTATION_WEIGHT) == {(s, k) for s in ("furuta", "nmsd") for k in ("adln", "aph")}
    assert all(w > 0 for w in AUGMENTATION_WEIGHT.values())
    cfg = TrainSettings.for_system(
        "nmsd", epochs=(2,), horizons=(None,), quadrature="simpson", progress=False, checkpoint_every=0
    )
    off = TrainSettings.for_system(
        "nmsd",
        epochs=(2,),
        horizons=(None,),
        quadrature="simpson",
        progress=False,
        checkpoint_every=0,
        augmentation_weight=0.0,
    )
    _, aph = train("aph", "nmsd", "prop", segments, off)
    _, adln = train("adln", "nmsd", "prop", segments, cfg)
    assert "fa_share" not in aph[-1] and aph[-1]["total"] == pytest.approx(aph[-1]["itau"], rel=1e-12)
    assert adln[-1]["fa_share"] > 0
    mu = AUGMENTATION_WEIGHT[("nmsd", "adln")]
    assert adln[-1]["total"] == pytest.approx(adln[-1]["itau"] + mu * adln[-1]["fa_share"], rel=1e-12)


def test_share_beyond_linear_leaves_the_viscous_term_free(segments):
    """augmentation_part='beyond_linear': P_a measures F_a − W·q̇ only, so a pure viscous F_a costs
    nothing while the full P_a of the same model does not vanish."""
    import equinox as eqx

    model = make_model("nmsd", "aph", jax.random.PRNGKey(3))
    w = make_windows(segments, 21, stride=20)
    viscous = eqx.tree_at(lambda m: m.force_net.linear, model, jnp.array([[-0.7]]))
    # zero the network's last layer: F_a is then exactly W·q̇ (times the scales)
    last = viscous.force_net.net.layers[-1]
    viscous = eqx.tree_at(
        lambda m: (m.force_net.net.layers[-1].weight, m.force_net.net.layers[-1].bias),
        viscous,
        (jnp.zeros_like(last.weight), jnp.zeros_like(last.bias)),
    )
    _, full = integral_loss_terms(viscous, w, with_augmentation=True)
    _, beyond = integral_loss_terms(viscous, w, with_augmentation=True, augmentation_part="beyond_linear")
    assert float(full) > 1e-3 and float(beyond) == 0.0
    # with a network part, beyond_linear measures exactly that part
    _, full0 = integral_loss_terms(model, w, with_augmentation=True)
    _, beyond0 = integral_loss_terms(model, w, with_augmentation=True, augmentation_part="beyond_linear")
    assert float(beyond0) == pytest.approx(float(full0), rel=1e-12)  # W starts at zero
    with pytest.raises(ValueError, match="augmentation_part must be one of"):
        TrainSettings(augmentation_part="linear")
