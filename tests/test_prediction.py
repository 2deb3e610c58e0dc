import casadi as ca
import numpy as np
from scipy import stats

from risk_env.models import dynamics
from risk_env.models.ops import CASADI
from risk_env.prediction.belief import Belief, predict, predict_array
from risk_env.scenario.scenario import Scenario

MEASUREMENT = np.array([5.0, -5.0, np.pi / 2, 3.0, 1e-4])


def test_mean_follows_the_unicycle_and_spread_grows_linearly():
    s = Scenario.preset("medium")
    b = predict_array(s, MEASUREMENT)
    traj = dynamics.rollout(MEASUREMENT[:3], MEASUREMENT[3:], s.dt, s.horizon)
    np.testing.assert_allclose(np.column_stack([b.x, b.y, b.theta]), traj, atol=1e-12)
    n = np.arange(s.horizon + 1)
    np.testing.assert_allclose(b.sigma_x, 0.8 * n)
    np.testing.assert_allclose(b.half_y, 2.0 * n)
    np.testing.assert_allclose(b.v_lo, -5.0 - 2.0 * n)
    np.testing.assert_allclose(b.v_hi, 5.0 + 2.0 * n)
    np.testing.assert_allclose(b.speed, 3.0)


def test_casadi_prediction_matches_numpy():
    s = Scenario.preset("high")
    m = ca.SX.sym("m", 5)
    sym = predict(s, m, ops=CASADI)
    f = ca.Function("f", [m], [ca.horzcat(*[ca.vertcat(b.x, b.y, b.theta) for b in sym])])
    ref = predict_array(s, MEASUREMENT)
    np.testing.assert_allclose(
        np.array(f(MEASUREMENT)).T, np.column_stack([ref.x, ref.y, ref.theta]), atol=1e-12
    )


def test_batched_measurements():
    s = Scenario.preset("low")
    ms = np.stack([MEASUREMENT, MEASUREMENT + 1.0])
    b = predict_array(s, ms)
    assert b.as_array().shape == (s.horizon + 1, 2, Belief.SIZE)
    np.testing.assert_allclose(b[:, 1].x, predict_array(s, ms[1]).x)


def test_samples_respect_truncation_and_match_truncated_normal_moments():
    s = Scenario.preset("high")
    b = predict_array(s, MEASUREMENT)[2]
    draws = b.sample(np.random.default_rng(3), 200_000)
    assert draws.shape == (200_000, 3)
    assert np.all(np.abs(draws[:, 0] - b.x) <= b.half_x + 1e-12)
    assert np.all((draws[:, 2] >= b.v_lo) & (draws[:, 2] <= b.v_hi))
    for col, mean, sigma, lo, hi in (
        (0, b.x, b.sigma_x, b.x - b.half_x, b.x + b.half_x),
        (2, b.speed, b.sigma_v, b.v_lo, b.v_hi),
    ):
        ref = stats.truncnorm((lo - mean) / sigma, (hi - mean) / sigma, loc=mean, scale=sigma)
        assert abs(draws[:, col].mean() - ref.mean()) < 5 * ref.std() / np.sqrt(len(draws))
        assert abs(draws[:, col].std() / ref.std() - 1) < 0.01


def test_sampling_is_seeded_and_degenerate_steps_are_points():
    s = Scenario.preset("low")
    b = predict_array(s, MEASUREMENT)
    a1 = b[1].sample(np.random.default_rng(7), 10)
    a2 = b[1].sample(np.random.default_rng(7), 10)
    np.testing.assert_array_equal(a1, a2)
    at_measurement = b[0].sample(np.random.default_rng(0), 5)
    np.testing.assert_allclose(at_measurement, np.tile([5.0, -5.0, 3.0], (5, 1)))


def test_far_tail_truncation_is_sampled_accurately():
    # an interval entirely 6 sigma above the mean: inverse-CDF on the mirrored tail keeps precision
    b = Belief(0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 6.0, 7.0)
    v = b.sample(np.random.default_rng(0), 50_000)[:, 2]
    ref = stats.truncnorm(6.0, 7.0)
    assert np.all((v >= 6.0) & (v <= 7.0))
    assert abs(v.mean() - ref.mean()) < 5 * ref.std() / np.sqrt(len(v))
