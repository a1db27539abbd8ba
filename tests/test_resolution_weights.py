"""L_Iτ weighted by how well the sampling resolves each interval's motion
(``TrainSettings.resolution_tolerance``; :func:`furuta_gym.training.losses.resolution_weights`)."""

import jax
import numpy as np
import pytest

from furuta_gym.data import Trajectory
from furuta_gym.lagrangian import quadrature_consistency
from furuta_gym.models import NMSD, Furuta, FurutaParameters, make_model
from furuta_gym.simulate import simulate
from furuta_gym.training.losses import integral_loss_terms, make_windows, resolution_weights
from furuta_gym.training.train import TrainSettings, train

DT = 0.01


def test_consistency_is_the_rules_error_on_the_velocity():
    t = np.arange(0.0, 1.0 + DT / 2, DT)
    # cubic motion: Simpson integrates its quadratic velocity exactly, the trapezoid does not
    q, qd = (t**3 - t)[:, None], (3 * t**2 - 1)[:, None]
    assert np.max(np.abs(quadrature_consistency(q, qd, DT, "simpson"))) < 1e-14
    trap = np.asarray(quadrature_consistency(q, qd, DT, "trapezoid"))
    # trapezoid error on f = 3t² − 1 over [a, a + h]: +h³ f''/12 = h³/2
    assert np.allclose(trap, DT**3 / 2, rtol=1e-9)
    # a sinusoid: Simpson's leading error over [a, a + 2h] is +(h⁵/90) f⁗(mid), f = ω cos ωt
    w = 12.0
    e = np.asarray(quadrature_consistency(np.sin(w * t)[:, None], (w * np.cos(w * t))[:, None], DT, "simpson"))
    mid = t[1:-1:2]
    assert np.allclose(e[:, 0], DT**5 / 90 * w**5 * np.cos(w * mid), rtol=0.02, atol=1e-12)


def _whirl(system, x0, seconds=2.0):
    t = np.arange(0.0, seconds + DT / 2, DT)
    u = np.zeros((len(t), 1))
    x = np.asarray(simulate(system, np.asarray(x0, float), t, u, rtol=1e-11, atol=1e-12))
    n = system.spec.n_dof
    return Trajectory(t, x[:, :n], u, x[:, n:])


@pytest.fixture(scope="module")
def furuta_data():
    # a slow swing, and a whirl at ~30 rad/s that 100 Hz samples barely resolve
    return [_whirl(Furuta(), [0.0, 0.5, 0.0, 0.0]), _whirl(Furuta(), [0.0, 0.5, 2.0, 30.0])]


def test_weights_follow_the_consistency_error_and_fall_on_the_fast_whirl(furuta_data):
    w = make_windows(furuta_data, 101, stride=100, cover_end=True)
    tol = 3e-6
    weights = np.asarray(resolution_weights(w, 2, "simpson", tol))
    for k in range(w.n_windows):
        x = np.asarray(w.x[k])
        e = np.asarray(quadrature_consistency(x[:, :2], x[:, 2:], DT, "simpson"))
        assert np.allclose(weights[k], 1 / (1 + np.sum(e**2, axis=1) / tol**2), rtol=1e-12)
    slow, fast = weights[: w.n_windows // 2], weights[w.n_windows // 2 :]
    assert np.median(slow) > 0.99
    assert fast.min() < 1e-3 and np.mean(fast < 0.1) > 0.1
    assert np.all(np.asarray(resolution_weights(w, 2, "simpson", None)) == 1.0)


def test_weighted_itau_of_the_true_model_drops_to_the_resolved_floor(furuta_data):
    w = make_windows(furuta_data, 101, stride=100, cover_end=True)
    truth = Furuta()
    plain = float(integral_loss_terms(truth, w, rule="simpson")[0])
    weighted = float(integral_loss_terms(truth, w, rule="simpson", resolution_tolerance=3e-6)[0])
    assert weighted < plain / 30  # 64x lower here, 560x on the reproduction's training data
    # a tolerance far above every interval's error weighs all intervals 1: the paper's sum
    loose = float(integral_loss_terms(truth, w, rule="simpson", resolution_tolerance=1.0)[0])
    assert loose == pytest.approx(plain, rel=1e-6)
    # a wrong pendulum damping still shows: weighting removes quadrature error, not physics
    wrong = Furuta(FurutaParameters(c_p=1.1 * 1.5e-5))
    wrong_weighted = float(integral_loss_terms(wrong, w, rule="simpson", resolution_tolerance=3e-6)[0])
    wrong_plain = float(integral_loss_terms(wrong, w, rule="simpson")[0])
    # the plain sum hardly sees a 10 % damping error above its floor (+4 %); weighted, it is 7x
    assert wrong_plain / plain < 1.1
    assert wrong_weighted / weighted > 5


def test_weighted_itau_stays_scale_free_on_free_data(furuta_data):
    w = make_windows(furuta_data, 101, stride=100, cover_end=True)
    m = make_model("furuta", "dln", jax.random.PRNGKey(0))
    a = float(integral_loss_terms(m, w, rule="simpson", normalize="momentum", resolution_tolerance=3e-6)[0])
    b = float(
        integral_loss_terms(m.with_scale(3.0), w, rule="simpson", normalize="momentum", resolution_tolerance=3e-6)[0]
    )
    assert b == pytest.approx(a, rel=1e-10)


def test_tolerance_must_be_positive():
    with pytest.raises(ValueError, match="resolution_tolerance must be positive or None, got 0"):
        TrainSettings(resolution_tolerance=0.0)
    tr = _whirl(NMSD(), [0.5, 0.0], seconds=0.5)
    with pytest.raises(ValueError, match="resolution_tolerance must be positive or None, got -1"):
        integral_loss_terms(NMSD(), make_windows([tr], 11, stride=10), resolution_tolerance=-1.0)


def test_training_with_the_weighting_records_it_and_lowers_itau(tmp_path):
    trs = [_whirl(NMSD(), [a, b], seconds=1.0) for a, b in [(0.8, 0.0), (-0.5, 2.0), (0.2, -3.0)]]
    cfg = TrainSettings.for_system(
        "nmsd",
        epochs=(30,),
        horizons=(None,),
        learning_rate=1e-2,
        quadrature="simpson",
        resolution_tolerance=1e-7,
        progress=False,
        checkpoint_every=0,
    )
    _, hist = train("dln", "nmsd", "itau", trs, cfg, out_dir=tmp_path)
    assert hist[-1]["itau"] < 0.5 * hist[0]["itau"]
    import json

    meta = json.loads((tmp_path / "history.json").read_text())["meta"]
    assert meta["config"]["resolution_tolerance"] == 1e-7
