"""The injury severity: its definition against momentum conservation, its expectation against
adaptive quadrature, its worst case against a dense grid, its faces, its coefficients' checks, and
the env, the agents and the highway wrapper running on it."""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import gymnasium as gym
import numpy as np
import pytest
from scipy import integrate

import risk_env  # noqa: F401  (registers RiskCrossing-v0)
from agents import RMPC, SMPC
from risk_env import Belief, Scenario, make_estimator, predict_array
from risk_env import observation as ob
from risk_env.models.ops import CASADI, MATH, NUMPY
from risk_env.risk.severity import InjurySeverity, make_severity
from risk_env.scenario.scenario import SEVERITY_NAMES

BETA0, BETA1 = -4.591, 0.185
"""Geisslinger et al. (2023), the MAIS3+ model without impact angle."""


def injury(**overrides) -> InjurySeverity:
    model = make_severity(Scenario(severity="injury").replace(**overrides))
    assert isinstance(model, InjurySeverity)
    return model


def by_momentum(v_e, th_e, v_o, th_o, m_e=1000.0, m_o=1000.0, b0=BETA0, b1=BETA1) -> float:
    """s from first principles: the common velocity after a perfectly plastic impact, each party's
    change of velocity, the logistic injury probability of each, summed."""
    ve = v_e * np.array([math.cos(th_e), math.sin(th_e)])
    vo = v_o * np.array([math.cos(th_o), math.sin(th_o)])
    common = (m_e * ve + m_o * vo) / (m_e + m_o)
    return sum(1.0 / (1.0 + math.exp(-(b0 + b1 * np.linalg.norm(common - v)))) for v in (ve, vo))


def reference_expectation(model: InjurySeverity, v_e: float, th_e: float, b: Belief) -> float:
    """E[s] by scipy's adaptive quadrature over the truncated Gaussian (density relative to its
    mode, so that far tails do not underflow), split at the mode and the least relative speed."""
    mu, sig, lo, hi = b.speed, b.sigma_v, b.v_lo, b.v_hi
    a, c = (lo - mu) / sig, (hi - mu) / sig
    z0 = min(max(0.0, a), c)

    def density(z):
        return math.exp(-0.5 * (z * z - z0 * z0))

    kink = (v_e * math.cos(th_e - b.theta) - mu) / sig
    left, right = max(a, z0 - 40.0), min(c, z0 + 40.0)
    points = sorted(p for p in (kink, z0) if left < p < right) or None
    opts = dict(points=points, epsabs=0.0, epsrel=1e-12, limit=500)

    def harm(z):
        return density(z) * float(model.value(v_e, th_e, mu + sig * z, b.theta, NUMPY))

    num = integrate.quad(harm, left, right, **opts)[0]
    return num / integrate.quad(density, left, right, **opts)[0]


def scalar_belief(speed, sigma_v, v_lo, v_hi, theta=0.3) -> Belief:
    return Belief(0.0, 0.0, theta, speed, 1.0, 1.0, sigma_v, 2.0, 2.0, v_lo, v_hi)


# ------------------------------------------------------------------------------------ the model
@pytest.mark.parametrize(("m_e", "m_o"), [(1000.0, 1000.0), (1500.0, 80.0)])
def test_value_is_the_plastic_impact_injury_count(m_e, m_o):
    model = injury(ego_mass=m_e, object_mass=m_o)
    rng = np.random.default_rng(0)
    for v_e, th_e, v_o, th_o in rng.uniform([-4, -4, -6, -4], [8, 4, 6, 4], (200, 4)):
        expected = by_momentum(v_e, th_e, v_o, th_o, m_e, m_o)
        assert float(model.value(v_e, th_e, v_o, th_o, NUMPY)) == pytest.approx(expected, rel=1e-12)
        assert model.value(float(v_e), float(th_e), float(v_o), float(th_o), MATH) == pytest.approx(
            expected, rel=1e-12
        )


def test_no_collision_is_free_and_harm_stays_below_two():
    model = injury()
    floor = 2.0 / (1.0 + math.exp(-BETA0))
    assert floor == pytest.approx(0.0201, abs=1e-4)
    # equal velocities: the floor; head-on at 8 m/s each: more; both bounded by 2
    assert float(model.value(3.0, 0.2, 3.0, 0.2, NUMPY)) == pytest.approx(floor, rel=1e-12)
    w = np.linspace(0.0, 200.0, 2001)  # relative speeds [m/s], ego against a still object
    s = model.value(w, 0.0, 0.0, 1.0, NUMPY)
    assert np.all(s >= floor - 1e-15) and np.all(s < 2.0) and np.all(np.diff(s) > 0)
    # a faster impact at a right angle: each party's delta-v is half the relative speed
    assert float(model.value(8.0, 0.0, 0.0, math.pi / 2, NUMPY)) == pytest.approx(
        2.0 / (1.0 + math.exp(-(BETA0 + BETA1 * 4.0)))
    )
    assert model.unit == "injuries" and model.upper_bound == 2.0


def test_uses_both_headings_unlike_the_papers_severity():
    """Equal speeds: the paper's severity is 0 whatever the directions; the injury count grows
    with the angle between them."""
    model, paper = injury(), make_severity(Scenario(severity="paper"))
    angles = np.linspace(0.0, math.pi, 7)
    s = model.value(4.0, 0.0, 4.0, angles, NUMPY)
    assert np.all(np.diff(s) > 0)
    np.testing.assert_array_equal(paper.value(4.0, 0.0, 4.0, angles, NUMPY), 0.0)


# ------------------------------------------------------------------------------ the expectation
def _cases(count: int, seed: int):
    """Ego speeds and headings against beliefs from tight to wide, means inside and outside their
    truncation interval, headings crossing, parallel, opposite and nearly parallel, ego at rest."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        mu = rng.uniform(-8, 8)
        sigma = 10 ** rng.uniform(-3, 1.2)
        lo = rng.uniform(-15, mu + 1)
        hi = rng.uniform(max(lo, mu - 1), 15)
        if hi <= lo:
            continue
        th_o = rng.uniform(-math.pi, math.pi)
        th_e = th_o + rng.choice([0.0, math.pi, rng.uniform(-math.pi, math.pi), 1e-3, rng.normal(0, 0.1)])
        v_e = rng.choice([rng.uniform(-5, 9), rng.normal(0, 0.1), 0.0])
        out.append((float(v_e), float(th_e), scalar_belief(mu, sigma, lo, hi, th_o)))
    return out


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")  # at 1e-12 relative
def test_expectation_matches_adaptive_quadrature():
    model = injury()
    cases = _cases(400, seed=1)
    # and the env's own beliefs at every preset and prediction step
    for preset in ("low", "medium", "high"):
        s = Scenario.preset(preset)
        beliefs = predict_array(s, np.array([5.0, -5.0, math.pi / 2, 3.0, 0.0]))
        for n in range(1, s.horizon + 1):
            b = beliefs[n]
            one = Belief(*(float(getattr(b, f.name)) for f in dataclasses.fields(Belief)))
            cases += [(v, th, one) for v, th in ((0.0, 0.0), (3.0, 0.0), (4.0, math.pi / 2), (-2.0, 1.0))]
    errors = []
    for v_e, th_e, b in cases:
        ref = reference_expectation(model, v_e, th_e, b)
        errors.append(abs(model.expected(v_e, th_e, b, MATH) - ref))
    assert max(errors) <= 1e-8, max(errors)


def test_expectation_faces_agree_and_gradients_are_finite():
    model = injury()
    cases = _cases(60, seed=2)
    cases.append((3.0, 0.3, scalar_belief(3.0, 0.0, 3.0, 3.0)))  # a point mass: the value there
    cases.append((0.0, 0.3, scalar_belief(0.0, 0.0, -1.0, 1.0)))  # ego and object at rest
    e, p = ca.SX.sym("e", 2), ca.SX.sym("p", Belief.SIZE)
    expr = model.expected(e[0], e[1], Belief.from_array(p), CASADI)
    f = ca.Function("f", [e, p], [expr, ca.gradient(expr, ca.vertcat(e, p))])
    batch = Belief(*(np.array([getattr(b, f.name) for *_, b in cases]) for f in dataclasses.fields(Belief)))
    v, th = np.array([c[0] for c in cases]), np.array([c[1] for c in cases])
    numpy_values = model.expected(v, th, batch, NUMPY)
    for i, (v_e, th_e, b) in enumerate(cases):
        value, grad = f([v_e, th_e], b.as_array())
        one = model.expected(v_e, th_e, b, MATH)
        assert float(value) == pytest.approx(one, rel=1e-12, abs=1e-15)
        assert numpy_values[i] == pytest.approx(one, rel=1e-12, abs=1e-15)
        assert np.all(np.isfinite(np.array(grad)))
    assert model.expected(3.0, 0.3, cases[-2][2], MATH) == pytest.approx(
        float(model.value(3.0, 0.3, 3.0, 0.3, NUMPY)), rel=1e-12
    )


def test_expectation_of_a_constant_severity_is_exact():
    """Zero slope in the limit: beta1 -> 0 makes s = 2 p(0) for every speed."""
    model = injury(injury_beta1=1e-300)
    for v_e, th_e, b in _cases(30, seed=3):
        assert model.expected(v_e, th_e, b, MATH) == pytest.approx(2.0 / (1.0 + math.exp(-BETA0)), rel=1e-14)


# ------------------------------------------------------------------------------- the worst case
def test_worst_is_the_maximum_over_a_dense_grid():
    """s grows with the relative speed, which is convex in v_o: its maximum over an interval sits
    at an end point. Check against 20,001 interior points."""
    model = injury()
    rng = np.random.default_rng(4)
    for _ in range(200):
        v_e, th_e, th_o = rng.uniform(-4, 8), rng.uniform(-math.pi, math.pi), rng.uniform(-math.pi, math.pi)
        if rng.random() < 0.3:
            th_o = th_e + rng.choice([0.0, math.pi])
        lo = rng.uniform(-10, 5)
        hi = lo + rng.uniform(0, 10)
        grid = model.value(v_e, th_e, np.linspace(lo, hi, 20_001), th_o, NUMPY)
        worst = float(model.worst(v_e, th_e, lo, hi, min(max(0.0, lo), hi), th_o, NUMPY))
        assert worst == pytest.approx(float(grid.max()), rel=1e-13)


# ------------------------------------------------------------------------------- the scenario
@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("injury_beta0", float("nan"), "injury_beta0 must be finite"),
        ("injury_beta1", float("nan"), "injury_beta1 must be finite"),
        ("injury_beta1", -0.185, "injury_beta1 must be > 0"),
        ("injury_beta1", 0.0, "injury_beta1 must be > 0"),
        ("injury_beta0", float("inf"), "injury_beta0 must be finite"),
    ],
)
def test_bad_coefficients_are_named(name, value, message):
    with pytest.raises(ValueError, match=message):
        Scenario.preset("low", severity="injury", **{name: value})
    with pytest.raises(ValueError, match=name):
        InjurySeverity(1000.0, 1000.0, **{"beta0": BETA0, "beta1": BETA1, name[-5:]: value})


def test_coefficients_are_overridable_everywhere():
    s = Scenario.preset("low", severity="injury", injury_beta0=-3.0, injury_beta1=0.3)
    assert (s.injury_beta0, s.injury_beta1) == (-3.0, 0.3)
    model = make_severity(s)
    assert float(model.value(0.0, 0.0, 0.0, 0.0, NUMPY)) == pytest.approx(2.0 / (1.0 + math.exp(3.0)))
    env = gym.make("RiskCrossing-v0", severity="injury", injury_beta0=-3.0)
    assert env.unwrapped.estimator.severity.beta0 == -3.0
    assert "injury" in SEVERITY_NAMES


# ------------------------------------------------------------------------- env, agents, wrapper
def test_env_reports_injuries():
    env = gym.make(
        "RiskCrossing-v0",
        severity="injury",
        uncertainty="high",
        object_start=(-5.0, 7.5, math.pi / 2),
        object_motion="sampled",
    )
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([4.0, 0.0], dtype=np.float32))
    assert 0.0 < info["risk"] < 2.0
    assert info["episode_risk"] == info["risk"]


@pytest.mark.parametrize(
    ("make", "estimator"),
    [
        (lambda sc: SMPC(sc, max_solve_time=math.inf), "exact"),
        (lambda sc: SMPC(sc, risk="monte_carlo", samples=100, seed=1, max_solve_time=math.inf), "exact"),
        (lambda sc: RMPC(sc, max_solve_time=math.inf), "worst_case"),
    ],
    ids=["smpc-exact", "smpc-monte-carlo", "rmpc"],
)
def test_agents_solve_with_the_injury_severity(make, estimator):
    """Closed loop past the object: every solve converges, and the exact SMPC's plans keep their
    risk within epsilon (up to the solver's tolerance on risk / scale). No wall-time cap: a busy
    machine must not turn a slow solve into a fallback."""
    epsilon = 0.004
    scenario = Scenario.preset("medium", severity="injury", risk_tolerance=epsilon, max_steps=12)
    env = gym.make("RiskCrossing-v0", scenario=scenario)
    agent = make(scenario)
    obs, _ = env.reset(seed=0)
    risks = []
    for _ in range(scenario.max_steps):
        action, _ = agent.predict(obs)
        report = agent.last_solve
        assert report.success and report.fallback is None
        beliefs = predict_array(scenario, ob.split(obs).object_measurement)[1:]
        ego = np.column_stack([report.ego_trajectory[1:], report.inputs[:, 0]])
        plan_risk = make_estimator(estimator, scenario).risk(ego, beliefs)
        if isinstance(agent, SMPC) and agent.risk_method == "exact":
            assert np.all(plan_risk <= epsilon + 1e-6), plan_risk
        obs, _, terminated, truncated, info = env.step(action)
        risks.append(info["risk"])
        if terminated or truncated:
            break
    assert agent.failures == 0 and not info["collision"]


def test_highway_wrapper_reports_injuries():
    pytest.importorskip("highway_env")
    from risk_env.highway import RiskCostWrapper, make_intersection_env

    env = RiskCostWrapper(make_intersection_env(), uncertainty="high", severity="injury")
    assert env.estimator.severity.name == "injury"
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(15):
        _, _, terminated, truncated, info = env.step(env.action_space.sample())
        assert all(0.0 <= r < 2.0 for r in info["risk_terms"].values())
        assert info["risk"] == pytest.approx(sum(info["risk_terms"].values()))
        if terminated or truncated:
            break
    env.close()
