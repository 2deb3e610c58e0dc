"""Beliefs in their own frame (``Belief.frame``): every estimator on both faces against independent
checks (rotating ego and belief together, brute force over the rotated box and grid, Monte Carlo
with many draws), draws in world coordinates, and clear errors on bad beliefs."""

import itertools
import math

import casadi as ca
import numpy as np
import pytest
from scipy import stats

from risk_env import ESTIMATOR_NAMES, Belief, Scenario, make_estimator, predict_array
from risk_env.models.frame import from_frame, to_frame
from risk_env.models.ops import MATH, NUMPY
from risk_env.risk import WorstCaseRisk
from risk_env.scenario import SEVERITY_NAMES

FRAME = 0.7
"""A frame angle [rad] that is no multiple of a right angle."""


def elongated(frame: float = FRAME, x: float = 2.0, y: float = -1.0) -> Belief:
    """A heading-aligned belief, 40:1: metres along, centimetres across."""
    return Belief(x, y, 0.4, 3.0, 2.0, 0.05, 0.5, 5.0, 0.15, 1.0, 5.0, frame)


def turned(belief: Belief, angle: float) -> Belief:
    """``belief`` turned by ``angle`` about the origin: its mean, heading and frame."""
    x, y = from_frame(belief.x, belief.y, angle)
    fields = dict(vars(belief), x=x, y=y, theta=belief.theta + angle, frame=belief.frame + angle)
    return Belief(**fields)


def turned_egos(egos: np.ndarray, angle: float) -> np.ndarray:
    x, y = from_frame(egos[:, 0], egos[:, 1], angle)
    return np.column_stack([x, y, egos[:, 2] + angle, egos[:, 3]])


def egos_around(belief: Belief, rng: np.random.Generator, n: int = 400, spread: float = 4.0) -> np.ndarray:
    return np.column_stack(
        [
            belief.x + rng.uniform(-spread, spread, n) * 2.0,
            belief.y + rng.uniform(-spread, spread, n),
            rng.uniform(-np.pi, np.pi, n),
            rng.uniform(-2.0, 6.0, n),
        ]
    )


def test_frames_turn_offsets_both_ways():
    rng = np.random.default_rng(0)
    d, f = rng.normal(0, 3, (2, 50)), rng.uniform(-4, 4, 50)
    along, across = to_frame(d[0], d[1], f)
    np.testing.assert_allclose(np.hypot(along, across), np.hypot(d[0], d[1]), rtol=1e-13)
    back = from_frame(along, across, f)
    np.testing.assert_allclose(back, d, atol=1e-12)
    # the frame's first axis: an offset along (cos f, sin f) is all "along"
    along, across = to_frame(np.cos(0.3), np.sin(0.3), 0.3)
    assert along == pytest.approx(1.0) and across == pytest.approx(0.0, abs=1e-15)
    assert to_frame(1.5, -2.5, 0.0) == (1.5, -2.5)  # frame 0: the offset itself, bit for bit


@pytest.mark.parametrize("name", ESTIMATOR_NAMES)
@pytest.mark.parametrize("severity", SEVERITY_NAMES)
def test_turning_ego_and_belief_together_leaves_the_risk_unchanged(name, severity):
    est = make_estimator(name, Scenario(severity=severity))
    b = elongated()
    egos = egos_around(b, np.random.default_rng(1))
    for angle in (0.9, -2.3, np.pi):
        other = turned(b, angle)
        if name == "monte_carlo":  # the same uniforms: the same draws in the frame
            base = est.risk(egos, b, rng=np.random.default_rng(3))
            got = est.risk(turned_egos(egos, angle), other, rng=np.random.default_rng(3))
        else:
            base = est.risk(egos, b)
            got = est.risk(turned_egos(egos, angle), other)
            assert 0.05 < np.mean(base > 0) < 0.95
        if name == "exact":
            np.testing.assert_allclose(got, base, rtol=1e-9, atol=1e-12 * est.severity.scale)
        else:  # the same but where a draw or the box lies on the disc edge to rounding
            same = np.isclose(got, base, rtol=1e-9, atol=1e-12 * est.severity.scale)
            assert np.mean(same) >= 0.99


def test_worst_case_is_the_distance_to_the_rotated_box():
    b = elongated()
    est = make_estimator("worst_case", Scenario())
    rng = np.random.default_rng(2)
    egos = egos_around(b, rng, 300)
    # brute force: the nearest of many points of the rotated box (its edges finely, its inside)
    u = np.linspace(-1.0, 1.0, 801)
    edge = np.concatenate([np.column_stack([u, s * np.ones_like(u)]) for s in (-1, 1)])
    edge = np.concatenate([edge, edge[:, ::-1]]) * [b.half_x, b.half_y]
    px, py = from_frame(edge[:, 0], edge[:, 1], b.frame)
    outside = np.hypot(egos[:, :1] - (b.x + px), egos[:, 1:2] - (b.y + py)).min(axis=1)
    along, across = to_frame(egos[:, 0] - b.x, egos[:, 1] - b.y, b.frame)
    inside = (np.abs(along) <= b.half_x) & (np.abs(across) <= b.half_y)
    d = est.distance(egos, b)
    assert 0 < np.mean(inside) < 0.5
    assert np.all(np.abs(d[~inside] - outside[~inside]) <= 2.0 * b.half_x / 800)
    assert np.all(d[inside] <= 0)


def test_grid_equals_the_brute_force_maximum_over_the_rotated_grid():
    s = Scenario.preset("high")
    b = elongated()
    est = WorstCaseRisk(s, grid=True, grid_points=7)
    u = np.linspace(-1.0, 1.0, 7)
    ax, ay = np.meshgrid(u * b.half_x, u * b.half_y)
    gx, gy = from_frame(ax.ravel(), ay.ravel(), b.frame)
    speeds = np.linspace(b.v_lo, b.v_hi, 7)
    for ego in egos_around(b, np.random.default_rng(4), 150):
        hit = np.hypot(ego[0] - (b.x + gx), ego[1] - (b.y + gy)) <= s.collision_distance
        brute = max(
            h * est.severity.value(ego[3], ego[2], v, b.theta, NUMPY)
            for h, v in itertools.product(hit, speeds)
        )
        assert float(est.risk(ego, b)) == pytest.approx(brute, abs=1e-9)


@pytest.mark.parametrize(
    "offset",
    [(0.0, 0.0), (2.5, 0.5), (-1.0, 2.9), (3.4, -1.6), (0.5, -3.05)],
    ids=["centre", "along", "edge across", "corner", "tangent"],
)
def test_exact_risk_within_a_monte_carlo_interval_on_a_rotated_elongated_belief(offset):
    s = Scenario(severity="probability")
    exact = make_estimator("exact", s)
    b = Belief(1.0, -2.0, 0.0, 3.0, 1.8, 0.04, 0.5, 4.0, 0.1, 1.0, 5.0, -1.1)
    ego = np.array([b.x + offset[0], b.y + offset[1], 0.0, 4.0])
    draws = b.sample(np.random.default_rng(5), 400_000)
    hit = np.hypot(ego[0] - draws[:, 0], ego[1] - draws[:, 1]) <= s.collision_distance
    estimate, stderr = hit.mean(), hit.std() / math.sqrt(len(hit))
    p = float(exact.risk(ego, b))
    assert abs(p - estimate) <= 4.5 * stderr + 1e-9, (p, estimate, stderr)
    assert 0.0 < p < 1.0


def test_draws_are_in_world_coordinates_inside_the_rotated_box():
    b = elongated()
    draws = b.sample(np.random.default_rng(6), 200_000)
    along, across = to_frame(draws[:, 0] - b.x, draws[:, 1] - b.y, b.frame)
    assert np.all(np.abs(along) <= b.half_x + 1e-12) and np.all(np.abs(across) <= b.half_y + 1e-12)
    for values, sigma, half in ((along, b.sigma_x, b.half_x), (across, b.sigma_y, b.half_y)):
        std = stats.truncnorm(-half / sigma, half / sigma, scale=sigma).std()
        assert np.std(values) == pytest.approx(std, rel=0.01) and abs(np.mean(values)) <= 0.01 * std
    assert np.all((draws[:, 2] >= b.v_lo) & (draws[:, 2] <= b.v_hi))
    u = np.random.default_rng(7).random((40, 3))
    batch = b.from_uniforms(u)
    one = np.array([MATH.pack(b.from_uniforms(row.tolist(), MATH)) for row in u])
    np.testing.assert_allclose(one, batch, rtol=1e-12, atol=1e-12)


def test_a_world_aligned_belief_samples_as_before():
    """Frame 0 (a number or an array of zeros): the paper's draws, bit for bit."""
    s = Scenario.preset("medium")
    b = predict_array(s, np.array([5.0, -5.0, 1.0, 3.0, 0.1]))
    assert b.as_array().shape[-1] == Belief.SIZE == 12 and not b.frame.any()
    world = Belief(
        *(getattr(b, f) for f in ("x", "y", "theta", "speed", "sigma_x", "sigma_y", "sigma_v")),
        b.half_x,
        b.half_y,
        b.v_lo,
        b.v_hi,
    )
    np.testing.assert_array_equal(
        b.sample(np.random.default_rng(8), 50), world.sample(np.random.default_rng(8), 50)
    )


@pytest.mark.parametrize("name", [n for n in ESTIMATOR_NAMES if n != "monte_carlo"])
def test_casadi_and_numpy_agree_on_rotated_beliefs(name):
    s = Scenario.preset("high", severity="plastic")
    est = make_estimator(name, s)
    e, p = ca.SX.sym("e", 4), ca.SX.sym("p", Belief.SIZE)
    f = ca.Function("f", [e, p], [est.casadi_risk(e, Belief.from_array(p))])
    g = ca.Function("g", [e, p], [ca.gradient(est.casadi_margin(e, Belief.from_array(p), 500.0), e)])
    rng = np.random.default_rng(9)
    for frame in (0.3, -2.0):
        b = elongated(frame)
        egos = egos_around(b, rng, 300)
        params = np.tile(b.as_array()[:, None], (1, len(egos)))
        sym = np.array(f.map(len(egos))(egos.T, params)).ravel()
        np.testing.assert_allclose(sym, est.risk(egos, b), rtol=1e-10, atol=1e-9)
        assert np.all(np.isfinite(np.array(g.map(len(egos))(egos.T, params))))


def test_the_solver_risk_stays_at_or_above_the_envs_on_rotated_beliefs():
    s = Scenario(severity="probability")
    est = make_estimator("exact", s)
    e, p = ca.SX.sym("e", 4), ca.SX.sym("p", Belief.SIZE)
    f = ca.Function("f", [e, p], [est.solver_risk(e, Belief.from_array(p))])
    rng = np.random.default_rng(10)
    for frame in (0.0, 1.2, -0.4):
        b = elongated(frame)
        egos = egos_around(b, rng, 500)
        params = np.tile(b.as_array()[:, None], (1, len(egos)))
        solver = np.array(f.map(len(egos))(egos.T, params)).ravel()
        env = est.risk(egos, b)
        assert np.all(solver >= env - 1e-12) and np.any(env > 0)


def test_the_mpc_sees_a_rotated_box_as_reachable():
    """The MPC's test of whether an object can matter (its box within the ego's reach, 15.25 m
    from rest at the low level, plus r = 3 m) turns the offset into the belief's frame: a long thin
    box along c2 is near an ego 35 m up c2 and far from one 25 m along c1 (its axis-aligned twin
    would be the other way round)."""
    from agents import RMPC

    agent = RMPC(Scenario.preset("low"), max_solve_time=math.inf)
    along_c2 = Belief(np.zeros(1), np.zeros(1), 0.0, 3.0, 3.0, 0.05, 0.5, 20.0, 0.2, 1.0, 5.0, math.pi / 2)
    along_c1 = Belief(**dict(vars(along_c2), frame=0.0))
    up, aside = np.array([0.0, 35.0, 0.0, 0.0, 0.0, 0.0]), np.array([25.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert agent._risk_possible(up, along_c2) and not agent._risk_possible(aside, along_c2)
    assert agent._risk_possible(aside, along_c1) and not agent._risk_possible(up, along_c1)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("sigma_x", -0.1, r"Belief.sigma_x must be finite and >= 0, got -0.1"),
        ("sigma_y", math.nan, r"Belief.sigma_y must be finite and >= 0, got nan"),
        ("sigma_v", math.inf, r"Belief.sigma_v must be finite and >= 0"),
        ("half_x", -1.0, r"Belief.half_x must be finite and >= 0"),
        (
            "half_y",
            np.array([0.2, np.nan]),
            r"Belief.half_y must be finite and >= 0, got .*nan.* among",
        ),
        ("frame", math.nan, r"Belief.frame must be a finite angle \[rad\], got nan"),
        ("frame", np.array([0.0, np.inf]), r"Belief.frame must be a finite angle"),
    ],
)
def test_bad_beliefs_are_named(field, value, message):
    fields = dict(vars(elongated()), **{field: value})
    with pytest.raises(ValueError, match=message):
        Belief(**fields)


def test_beliefs_check_numbers_not_symbols_and_round_trip_their_frame():
    b = elongated()
    back = Belief.from_array(b.as_array())
    assert float(back.frame) == FRAME and back.as_array().shape == (Belief.SIZE,)
    Belief.from_array(ca.SX.sym("p", Belief.SIZE))  # symbols pass unchecked
    with pytest.raises(ValueError, match="last axis of 12"):
        Belief.from_array(np.zeros(11))
    assert Belief(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0).frame == 0.0  # a point mass is fine
