import math

import casadi as ca
import numpy as np
import pytest
from scipy import integrate, special, stats

from risk_env import ESTIMATOR_NAMES, Belief, Scenario, make_estimator, predict_array
from risk_env.models.ops import CASADI, NUMPY
from risk_env.risk.estimators import WorstCaseRisk, disc_probability, signed_box_distance
from risk_env.risk.quadrature import SOLVER_SHORTFALL, SOLVER_SIGMA_BREAKS, SOLVER_SUPPORT
from risk_env.scenario.scenario import SEVERITY_NAMES

MEASUREMENT = np.array([5.0, -5.0, np.pi / 2, 3.0, 1e-4])


def belief(preset: str, n: int, severity: str = "paper") -> tuple[Scenario, Belief]:
    s = Scenario.preset(preset, severity=severity)
    return s, predict_array(s, MEASUREMENT)[n]


def reference_probability(dx, dy, r, sx, sy, hx, hy):
    """P(disc) by adaptive quadrature of the truncated density (independent of the fixed-node rule).
    The standard normal's CDF is scipy's ``ndtr`` and its density ``exp(-z^2 / 2) / sqrt(2 pi)``, as
    in ``scipy.stats.norm`` but without its per-call overhead (quad calls them thousands of times)."""
    cdf = special.ndtr
    zx = cdf(hx / sx) - cdf(-hx / sx)
    zy = cdf(hy / sy) - cdf(-hy / sy)

    def inner(x):
        w = np.sqrt(max(r * r - (x - dx) ** 2, 0.0))
        lo, hi = max(-hy, dy - w), min(hy, dy + w)
        density = math.exp(-0.5 * (x / sx) ** 2) / math.sqrt(2.0 * math.pi) / sx
        return 0.0 if hi <= lo else density * (cdf(hi / sy) - cdf(lo / sy))

    lo, hi = max(-hx, dx - r), min(hx, dx + r)
    if hi <= lo:
        return 0.0
    cuts = [k * sx for k in (-3, -1, 0, 1, 3)]
    cuts += [dx + sg * np.sqrt(max(r * r - (c - dy) ** 2, 0)) for c in (hy, -hy, 0) for sg in (-1, 1)]
    pts = sorted(p for p in set(cuts) if lo < p < hi)
    value, _ = integrate.quad(inner, lo, hi, points=pts or None, limit=500, epsabs=1e-13, epsrel=1e-11)
    return value / (zx * zy)


@pytest.mark.parametrize(
    "case",
    [
        (0.3, 0.2, 0.1, 0.1, 1.0, 1.0),  # low preset, n = 1, object inside the disc
        (3.05, 0.1, 0.1, 0.1, 1.0, 1.0),  # disc edge through the object's mean, sharp Gaussian
        (2.0, -2.9, 0.8, 0.8, 2.0, 2.0),  # medium, truncation active
        (4.0, -0.2, 0.42, 0.45, 4.2, 4.5),
        (-1.2, 3.3, 1.5, 1.7, 3.0, 3.4),  # anisotropic, box cuts the disc
        (9.0, 6.0, 4.5, 4.5, 9.0, 9.0),  # high preset, far
        (25.0, 0.0, 1.0, 1.0, 6.0, 6.0),  # disc misses the box: exactly 0
    ],
)
def test_disc_probability_matches_adaptive_quadrature(case):
    dx, dy, sx, sy, hx, hy = case
    b = Belief(0.0, 0.0, 0.0, 3.0, sx, sy, 1.0, hx, hy, -5.0, 5.0)
    p = float(disc_probability(dx, dy, 3.0, b))
    assert p == pytest.approx(reference_probability(dx, dy, 3.0, sx, sy, hx, hy), abs=5e-5)


def test_disc_probability_is_exactly_zero_off_the_box_and_positive_on_it():
    b = Belief(0.0, 0.0, 0.0, 3.0, 1.0, 1.0, 1.0, 2.0, 2.0, -5.0, 5.0)
    assert disc_probability(5.0 + 1e-6, 0.5, 3.0, b) == 0.0
    assert disc_probability(5.0 - 1e-3, 0.5, 3.0, b) > 0.0


@pytest.mark.parametrize("severity", ["paper", "plastic"])
@pytest.mark.parametrize("v_e", [0.0, 1.7, 3.0, 4.5, -2.0])
def test_expected_severity_closed_form(severity, v_e):
    s, b = belief("high", 2, severity)
    est = make_estimator("exact", s)
    th_e = 0.4
    dist = stats.truncnorm(
        (b.v_lo - b.speed) / b.sigma_v, (b.v_hi - b.speed) / b.sigma_v, loc=b.speed, scale=b.sigma_v
    )
    ref = dist.expect(
        lambda v: est.severity.value(v_e, th_e, v, b.theta, NUMPY), points=[-abs(v_e), abs(v_e)]
    )
    assert float(est.severity.expected(v_e, th_e, b, NUMPY)) == pytest.approx(ref, rel=1e-7, abs=1e-6)


@pytest.mark.parametrize(
    ("preset", "n", "ego", "label"),
    [
        ("low", 1, (5.0, -2.6, 0.0, 4.0), "overlapping"),
        ("medium", 2, (6.0, -0.5, 0.3, 4.0), "truncation active"),
        ("high", 4, (8.0, 4.0, 0.2, 2.0), "wide spread"),
        ("medium", 3, (20.0, 0.0, 0.0, 4.0), "far away"),
    ],
)
@pytest.mark.parametrize("severity", SEVERITY_NAMES)
def test_exact_risk_within_monte_carlo_confidence_interval(preset, n, ego, label, severity):
    s, b = belief(preset, n, severity)
    exact = float(make_estimator("exact", s).risk(np.array(ego), b))
    mc = make_estimator("monte_carlo", s, samples=400_000)
    draws = b.sample(np.random.default_rng(11), 400_000)
    hit = np.hypot(ego[0] - draws[:, 0], ego[1] - draws[:, 1]) <= 3.0
    terms = hit * mc.severity.value(ego[3], ego[2], draws[:, 2], b.theta, NUMPY)
    estimate, stderr = terms.mean(), terms.std() / np.sqrt(len(terms))
    assert float(mc.risk(np.array(ego), b, draws=draws)) == pytest.approx(estimate)
    if label == "far away":
        assert exact == 0.0 and estimate == 0.0
    else:
        assert exact > 0
        assert abs(exact - estimate) <= 4.5 * stderr + 1e-9 * abs(exact), (label, exact, estimate, stderr)


@pytest.mark.parametrize("severity", SEVERITY_NAMES)
def test_worst_case_bounds_exact_and_grid_under_approximates(severity):
    rng = np.random.default_rng(5)
    s, b = belief("medium", 3, severity)
    egos = np.column_stack(
        [rng.normal(5, 8, 2000), rng.normal(2, 8, 2000), rng.uniform(-3, 3, 2000), rng.uniform(-4, 8, 2000)]
    )
    exact = make_estimator("exact", s).risk(egos, b)
    worst = make_estimator("worst_case", s).risk(egos, b)
    grid = make_estimator("grid", s).risk(egos, b)
    assert np.all(exact >= 0)
    assert np.all(worst >= exact - 1e-9)
    assert np.all(grid <= worst + 1e-9)
    assert np.any(worst > 0) and np.any(worst == 0)


def test_grid_equals_the_brute_force_maximum_over_l_cubed_points():
    s, b = belief("high", 2)
    est = WorstCaseRisk(s, grid=True, grid_points=9)
    cx = np.linspace(b.x - b.half_x, b.x + b.half_x, 9)
    cy = np.linspace(b.y - b.half_y, b.y + b.half_y, 9)
    vo = np.linspace(b.v_lo, b.v_hi, 9)
    rng = np.random.default_rng(2)
    for ego in np.column_stack(
        [rng.normal(b.x, 10, 300), rng.normal(b.y, 10, 300), rng.uniform(-3, 3, 300), rng.uniform(-4, 8, 300)]
    ):
        x, y, v = (a.ravel() for a in np.meshgrid(cx, cy, vo, indexing="ij"))  # the 9^3 points
        inside = np.hypot(ego[0] - x, ego[1] - y) <= 3.0
        brute = np.max(inside * est.severity.value(ego[3], ego[2], v, b.theta, NUMPY))
        assert float(est.risk(ego, b)) == pytest.approx(brute, abs=1e-9)


def test_grid_converges_to_the_exact_box_form():
    s, b = belief("high", 4)
    rng = np.random.default_rng(4)
    egos = np.column_stack(
        [rng.normal(b.x, 12, 4000), rng.normal(b.y, 12, 4000), np.zeros(4000), rng.uniform(-4, 8, 4000)]
    )
    box = make_estimator("worst_case", s)
    d_box = box.distance(egos, b)
    gaps = []
    for points in (5, 40, 400):
        grid = WorstCaseRisk(s, grid=True, grid_points=points)
        gap = grid.distance(egos, b) - np.maximum(d_box, 0.0)
        assert np.all(gap >= -1e-6)
        gaps.append(gap.max())
        mismatch = np.mean(grid.risk(egos, b) != box.risk(egos, b))
        assert mismatch <= 2.0 / points
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[2] <= np.hypot(b.half_x, b.half_y) / 399 + 1e-6


def test_signed_box_distance():
    assert signed_box_distance(5.0, 0.0, 2.0, 1.0) == pytest.approx(3.0, abs=1e-6)
    assert signed_box_distance(5.0, 5.0, 2.0, 1.0) == pytest.approx(5.0, abs=1e-6)
    assert signed_box_distance(0.5, 0.0, 2.0, 1.0) == pytest.approx(-1.0, abs=1e-6)


@pytest.mark.parametrize("name", [n for n in ESTIMATOR_NAMES if n != "monte_carlo"])
@pytest.mark.parametrize("severity", SEVERITY_NAMES)
def test_casadi_and_numpy_forms_agree(name, severity):
    s = Scenario.preset("high", severity=severity)
    beliefs = predict_array(s, MEASUREMENT)
    est = make_estimator(name, s)
    e, p = ca.SX.sym("e", 4), ca.SX.sym("p", Belief.SIZE)
    f = ca.Function("f", [e, p], [est.casadi_risk(e, Belief.from_array(p))])
    g = ca.Function("g", [e, p], [ca.gradient(est.casadi_margin(e, Belief.from_array(p), 500.0), e)])
    rng = np.random.default_rng(8)
    egos = np.column_stack(
        [rng.normal(5, 7, 300), rng.normal(0, 7, 300), rng.uniform(-3, 3, 300), rng.uniform(-4, 8, 300)]
    )
    for n in (1, 3, 6):
        b = beliefs[n]
        params = np.tile(b.as_array()[:, None], (1, len(egos)))
        sym = np.array(f.map(len(egos))(egos.T, params)).ravel()
        np.testing.assert_allclose(sym, est.risk(egos, b), rtol=1e-10, atol=1e-9)
        assert np.all(np.isfinite(np.array(g.map(len(egos))(egos.T, params))))


def test_smoothed_monte_carlo_tends_to_the_hard_indicator():
    s, b = belief("medium", 2)
    draws = b.sample(np.random.default_rng(0), 2000)
    ego = np.array([6.0, 1.0, 0.2, 4.0])
    hard = float(make_estimator("monte_carlo", s).risk(ego, b, draws=draws))
    e, d = ca.SX.sym("e", 4), ca.SX.sym("d", 2000, 3)
    errors = []
    for bandwidth, severity_smoothing in ((0.2, 0.2), (0.05, 0.05), (0.002, 0.001)):
        est = make_estimator("monte_carlo", s, bandwidth=bandwidth, severity_smoothing=severity_smoothing)
        f = ca.Function("f", [e, d], [est.casadi_risk(e, b, samples=d)])
        errors.append(abs(float(f(ego, draws)) - hard))
    assert hard > 0 and errors[0] > errors[2] and errors[2] < 0.005 * hard
    fixed = make_estimator("monte_carlo", s, smoothing=0.005, severity_smoothing=0.0)  # the fixed width
    f = ca.Function("f", [e, d], [fixed.casadi_risk(e, b, samples=d)])
    assert abs(float(f(ego, draws)) - hard) < 0.02 * hard


@pytest.mark.parametrize("preset", ["low", "medium", "high"])
@pytest.mark.parametrize("severity", SEVERITY_NAMES)
def test_smoothed_monte_carlo_within_its_stated_bound_of_the_hard_estimator(preset, severity):
    """The solver's form against the paper's (numpy, hard indicator) on the same draws: within
    ``smoothing_bound`` everywhere, and the bound is small where the draws are dense."""
    s = Scenario.preset(preset, severity=severity)
    beliefs = predict_array(s, MEASUREMENT)
    est = make_estimator("monte_carlo", s)
    rng = np.random.default_rng(11)
    e, d = ca.SX.sym("e", 4), ca.SX.sym("d", est.samples, 3)
    for n in (1, 3, 6):
        b = beliefs[n]
        f = ca.Function("f", [e, d], [est.casadi_risk(e, b, samples=d)])
        draws = b.sample(rng, est.samples)
        # ego centres around the draws' cloud: inside, on the disc edge, outside
        spread = float(np.sqrt(b.sigma_x * b.sigma_y)) + s.collision_distance
        egos = np.column_stack(
            [
                rng.normal(b.x, spread, 200),
                rng.normal(b.y, spread, 200),
                rng.uniform(-3, 3, 200),
                rng.uniform(-4, 8, 200),
            ]
        )
        smooth = np.array(f.map(len(egos))(egos.T, draws)).ravel()
        hard = est.risk(egos, b, draws=draws)
        bound = est.smoothing_bound(egos, b, draws)
        assert np.all(np.abs(smooth - hard) <= bound + 1e-9), np.max(np.abs(smooth - hard) - bound)
        assert np.all(smooth >= 0)
        worst = float(np.max(est.severity.value(egos[:, 3], 0.0, draws[:, 2, None], b.theta, NUMPY)))
        assert np.median(bound) <= 0.05 * worst + est.severity_width


def test_smoothed_monte_carlo_bias_in_expectation_is_small():
    """Many draws: the smoothed estimator is within MC noise plus its O(bandwidth^2) bias of the
    exact risk (the expectation the paper's estimator estimates)."""
    s, b = belief("medium", 3)
    exact = make_estimator("exact", s)
    est = make_estimator("monte_carlo", s, samples=40000)
    draws = b.sample(np.random.default_rng(5), est.samples)
    e, d = ca.SX.sym("e", 4), ca.SX.sym("d", est.samples, 3)
    f = ca.Function("f", [e, d], [est.casadi_risk(e, b, samples=d)])
    for dx, dy, v in ((0.0, 0.0, 4.0), (3.5, 1.0, 3.0), (-2.0, 4.0, 2.5), (5.0, 3.0, 6.0)):
        ego = np.array([float(b.x) + dx, float(b.y) + dy, 0.3, v])
        hard = float(est.risk(ego, b, draws=draws))
        smooth = float(f(ego, draws))
        reference = float(exact.risk(ego, b))
        noise = (
            3
            * np.std(
                (np.hypot(ego[0] - draws[:, 0], ego[1] - draws[:, 1]) <= est.radius)
                * est.severity.value(v, 0.3, draws[:, 2], b.theta, NUMPY)
            )
            / np.sqrt(est.samples)
        )
        assert abs(hard - reference) <= noise + 1.0
        assert abs(smooth - reference) <= noise + 0.01 * max(reference, 100.0) + est.severity_width


@pytest.mark.parametrize("severity", SEVERITY_NAMES)
def test_smooth_severity_lies_within_its_width_above_the_severity(severity):
    from risk_env.risk.severity import make_severity

    model = make_severity(Scenario(severity=severity))
    v_e, v_o = np.meshgrid(np.linspace(-4, 8, 61), np.linspace(-6, 6, 61))
    value = model.value(v_e, 0.2, v_o, 1.0, NUMPY)
    np.testing.assert_array_equal(model.smooth_value(v_e, 0.2, v_o, 1.0, NUMPY, 0.0), value)
    smooth = model.smooth_value(v_e, 0.2, v_o, 1.0, NUMPY, 50.0)
    assert np.all(smooth >= value - 1e-9) and np.all(smooth <= value + 50.0 + 1e-9)


def test_worst_case_margin_relaxes_when_tolerance_exceeds_worst_severity():
    s, b = belief("low", 2, "probability")
    est = make_estimator("worst_case", s)
    e = ca.SX.sym("e", 4)
    margin = ca.Function("m", [e], [est.casadi_margin(e, b, 1.0)])
    strict = ca.Function("m", [e], [est.casadi_margin(e, b, 0.5)])
    inside = [float(b.x), float(b.y), 0.0, 4.0]
    assert float(est.risk(np.array(inside), b)) == 1.0
    assert float(margin(inside)) >= 0.0 > float(strict(inside))


def test_bad_arguments():
    s = Scenario()
    with pytest.raises(ValueError, match="unknown risk estimator 'exakt'"):
        make_estimator("exakt", s)
    with pytest.raises(ValueError, match="rng"):
        make_estimator("monte_carlo", s).risk(np.zeros(4), predict_array(s, MEASUREMENT)[1])
    with pytest.raises(ValueError, match="samples"):
        make_estimator("monte_carlo", s, samples=0)
    with pytest.raises(ValueError, match="bandwidth"):
        make_estimator("monte_carlo", s, bandwidth=0.0)
    with pytest.raises(ValueError, match="severity_smoothing"):
        make_estimator("monte_carlo", s, severity_smoothing=-1.0)
    with pytest.raises(ValueError, match="last axis of 4"):
        make_estimator("exact", s).risk(np.zeros(3), predict_array(s, MEASUREMENT)[1])


def test_exact_risk_skips_only_states_whose_disc_misses_the_box():
    s = Scenario.preset("high")
    est = make_estimator("exact", s)
    beliefs = predict_array(s, MEASUREMENT)
    rng = np.random.default_rng(3)
    egos = np.column_stack(
        [rng.normal(5, 10, 600), rng.normal(0, 10, 600), rng.uniform(-3, 3, 600), rng.uniform(-4, 8, 600)]
    )
    b = beliefs[3]
    full = np.asarray(est._risk(egos, b, NUMPY))
    far = signed_box_distance(egos[:, 0] - b.x, egos[:, 1] - b.y, b.half_x, b.half_y) >= 3.0
    assert 0.2 < np.mean(~far) < 0.9  # a mixed batch: near and far states
    got = est.risk(egos, b)
    assert np.all(got[far] == 0.0) and np.all(full[far] == 0.0)
    # the numpy kernel against the generic form: equal to rounding (P to 1e-12, times E[s])
    scale = np.asarray(est.severity.expected(egos[:, 3], egos[:, 2], b, NUMPY))
    assert np.all(np.abs(got - full) <= 1e-12 * scale)
    steps = np.broadcast_to(egos[0], (s.horizon + 1, 4))  # one ego state against every step's belief
    full_steps = np.asarray(est._risk(steps, beliefs, NUMPY))
    scale = np.asarray(est.severity.expected(steps[:, 3], steps[:, 2], beliefs, NUMPY))
    assert np.all(np.abs(est.risk(steps, beliefs) - full_steps) <= 1e-12 * scale)
    assert float(est.risk(np.array([60.0, 60.0, 0.0, 4.0]), beliefs[1])) == 0.0


@pytest.mark.parametrize(
    ("case", "kink"),
    [
        ((0.3, 0.2, 0.1, 0.1, 1.0, 1.0), False),  # low preset, n = 1, object inside the disc
        ((2.9, 0.4, 0.3, 0.3, 3.0, 3.0), False),  # low, n = 3: disc edge
        ((2.0, -2.9, 0.8, 0.8, 2.0, 2.0), False),  # medium, truncation active
        ((4.0, -0.2, 0.42, 0.45, 4.2, 4.5), False),  # a slightly anisotropic box
        ((-1.2, 3.3, 1.5, 1.7, 3.0, 3.4), False),  # anisotropic, the box cuts the disc
        ((-4.0, 3.9, 1.5, 1.5, 3.0, 3.0), True),  # high, n = 1: the disc over the box's corner
        ((9.0, 6.0, 4.5, 4.5, 9.0, 9.0), True),  # high, the disc on the box's corner
    ],
)
def test_disc_probability_derivatives_are_the_integrals(case, kink):
    """The CasADi face's derivatives (edges held, Leibniz nodes at the range's ends) against
    finite differences of the adaptive quadrature. The gradient is P's. So is the Hessian, but
    for the motion of the kinks where a chord's end crosses the box's inner edge (``kink``):
    a rank-one term per kink, left out (it changes the solver's steps, not its solution)."""
    dx, dy, sx, sy, hx, hy = case
    d = ca.SX.sym("d", 2)
    b = Belief(0.0, 0.0, 0.0, 3.0, sx, sy, 1.0, hx, hy, -5.0, 5.0)
    p = disc_probability(d[0], d[1], 3.0, b, CASADI)
    hessian, gradient = ca.hessian(p, d)
    value, grad, hess = (np.asarray(a) for a in ca.Function("f", [d], [p, gradient, hessian])([dx, dy]))
    at, e = np.array([dx, dy]), np.eye(2)

    def ref(x: np.ndarray) -> float:
        return reference_probability(x[0], x[1], 3.0, sx, sy, hx, hy)

    h = 1e-4
    fd_grad = np.array([(ref(at + h * e[i]) - ref(at - h * e[i])) / (2 * h) for i in range(2)])
    h = 2e-3
    fd_hess = np.array(
        [
            [
                (
                    ref(at + h * (e[i] + e[j]))
                    - ref(at + h * (e[i] - e[j]))
                    - ref(at - h * (e[i] - e[j]))
                    + ref(at - h * (e[i] + e[j]))
                )
                / (4 * h * h)
                for j in range(2)
            ]
            for i in range(2)
        ]
    )
    assert value.item() == pytest.approx(ref(at), abs=5e-5)
    scale = max(np.max(np.abs(fd_grad)), 1e-3)
    np.testing.assert_allclose(grad.ravel(), fd_grad, atol=2e-3 * scale + 1e-6)
    scale = max(np.max(np.abs(fd_hess)), 1e-3)
    missing = hess - fd_hess
    if not kink:
        np.testing.assert_allclose(hess, fd_hess, atol=1e-2 * scale)
    else:  # what is left out has rank one
        assert abs(np.linalg.det(missing)) <= 1e-2 * np.sum(missing**2) + (1e-2 * scale) ** 2


def test_stop_derivative_holds_the_value_and_drops_the_derivative():
    x = ca.SX.sym("x")
    held = CASADI.stop_derivative(ca.sin(x))
    picked = CASADI.select(x > 0, x * x, 3 * x)
    f = ca.Function("f", [x], [held, ca.jacobian(held, x), picked, ca.jacobian(picked, x)])
    for value in (-1.3, -1e-9, 0.0, 0.7, 1.5707963267948966):
        h, dh, p, dp = (float(a) for a in f(value))
        assert abs(h - np.sin(value)) <= 2.0**-51 and dh == 0.0
        assert p == (value * value if value > 0 else 3 * value)
        assert dp == (2 * value if value > 0 else 3.0)
    assert NUMPY.stop_derivative(0.3) == 0.3
    assert NUMPY.select(np.array([True, False]), 1.0, 2.0).tolist() == [1.0, 2.0]


def test_solver_rule_falls_short_of_the_envs_by_at_most_its_bound():
    """The MPC's rule (cut at +-5 sigma) against the env's (+-7): not above it (to 1e-9), below it
    by at most SOLVER_SHORTFALL, on random geometries (boxes from 0.05 to 12 sigma, so the cut binds on
    many) and along the paper's predictions; the margin it adds back makes ExactRisk's solver R
    at or above the env's R."""
    rng = np.random.default_rng(17)
    n = 20000
    s = np.exp(rng.uniform(np.log(0.02), np.log(6.0), (n, 2)))
    s[::3, 1] = s[::3, 0]
    h = s * np.exp(rng.uniform(np.log(0.05), np.log(12.0), (n, 2)))
    d = rng.uniform(-1, 1, (n, 2)) * (h + 3.0)
    b = Belief(0.0, 0.0, 0.0, 3.0, s[:, 0], s[:, 1], 1.0, h[:, 0], h[:, 1], -5.0, 5.0)
    env_rule = disc_probability(d[:, 0], d[:, 1], 3.0, b)
    solver_rule = disc_probability(
        d[:, 0], d[:, 1], 3.0, b, sigma_breaks=SOLVER_SIGMA_BREAKS, support=SOLVER_SUPPORT
    )
    shortfall = env_rule - solver_rule
    # (-1e-9: the env rule's own quadrature error on its tail segments, where P is ~1e-10)
    assert np.all(shortfall >= -1e-9) and np.all(shortfall <= SOLVER_SHORTFALL + 1e-12)
    assert np.max(shortfall) > 0.1 * SOLVER_SHORTFALL  # the cut bound somewhere
    for preset in ("low", "medium", "high"):
        sc = Scenario.preset(preset)
        est = make_estimator("exact", sc)
        e, p = ca.SX.sym("e", 4), ca.SX.sym("p", Belief.SIZE)
        f = ca.Function("f", [e, p], [est.solver_risk(e, Belief.from_array(p))])
        egos = np.column_stack(
            [rng.normal(5, 6, 400), rng.normal(-2, 6, 400), rng.uniform(-3, 3, 400), rng.uniform(-4, 8, 400)]
        )
        for belief_n in predict_array(sc, MEASUREMENT)[1:]:
            params = np.tile(belief_n.as_array()[:, None], (1, len(egos)))
            solver = np.array(f.map(len(egos))(egos.T, params)).ravel()
            env = est.risk(egos, belief_n)
            scale = np.asarray(est.severity.expected(egos[:, 3], egos[:, 2], belief_n, NUMPY))
            assert np.all(solver >= env - 1e-9)
            assert np.all(solver <= env + (SOLVER_SHORTFALL + 1e-9) * scale)
            off = signed_box_distance(
                egos[:, 0] - belief_n.x, egos[:, 1] - belief_n.y, belief_n.half_x, belief_n.half_y
            )
            assert np.all(solver[off >= 3.0] == 0.0) and np.any(off >= 3.0)  # off the box: exactly 0
