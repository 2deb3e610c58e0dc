"""Vehicles as several discs along their heading (risk_env.risk.bodies): the scenario's bodies, the
cover of a car, the worst case exact for the bodies and the expectation an upper bound on theirs."""

from __future__ import annotations

import math

import casadi as ca
import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import risk_env  # noqa: F401  (registers RiskCrossing-v0)
from agents import RMPC, SMPC
from risk_env import Scenario, make_estimator, predict_array
from risk_env import observation as ob
from risk_env.models.ops import NUMPY
from risk_env.prediction.belief import Belief
from risk_env.risk.bodies import BodyRisk, cover_radius, moved_belief, moved_draws, moved_ego, stretched
from risk_env.scenario.parts import disc_offsets

CAR = {"discs": 3, "length": 5.0, "radius": cover_radius(5.0, 2.0, 3)}
BODIES = {f"{who}_{k}": v for who in ("ego", "object") for k, v in CAR.items()}


def point(x: float, y: float, theta: float, half: float = 0.0, sigma: float = 0.0) -> Belief:
    """A belief at ``(x, y)`` heading ``theta``, its frame along the heading."""
    return Belief(x, y, theta, 5.0, sigma, sigma, 0.1, half, half, 4.0, 6.0, frame=theta)


def test_the_discs_sit_at_the_middles_of_equal_pieces_and_bad_bodies_are_named():
    assert disc_offsets(1, 5.0) == (0.0,)
    assert np.allclose(disc_offsets(3, 6.0), (-2.0, 0.0, 2.0))
    s = Scenario.preset("low", ego_discs=2, ego_length=4.0)
    assert np.allclose(s.ego.disc_offsets, (-1.0, 1.0)) and s.object.disc_offsets == (0.0,)
    with pytest.raises(ValueError, match="ego.discs"):
        Scenario.preset("low", ego_discs=0)
    with pytest.raises(TypeError, match="object.discs"):
        Scenario.preset("low", object_discs=2.0)
    with pytest.raises(ValueError, match="object.length"):
        Scenario.preset("low", object_discs=3)  # several discs need a length
    with pytest.raises(ValueError, match="ego.length"):
        Scenario.preset("low", ego_length=math.nan)


def test_the_cover_radius_covers_the_car():
    length, width, n = 5.0, 2.0, 3
    r = cover_radius(length, width, n)
    xs, ys = np.meshgrid(np.linspace(-length / 2, length / 2, 51), np.linspace(-width / 2, width / 2, 21))
    centres = np.array(disc_offsets(n, length))
    nearest = np.min(np.hypot(xs[..., None] - centres, ys[..., None]), axis=-1)
    assert nearest.max() <= r + 1e-12
    assert nearest.max() > r - 1e-9  # the corners: no smaller radius covers it


def test_one_disc_each_keeps_the_single_disc_estimator():
    est = make_estimator("exact", Scenario.preset("low"))
    assert not isinstance(est, BodyRisk)
    assert isinstance(make_estimator("exact", Scenario.preset("low", **BODIES)), BodyRisk)


def test_cars_side_by_side_in_adjacent_lanes_touch_as_discs_not_as_bodies():
    """Two 2 m discs touch at the lanes' 4 m; three 1.3 m discs per car leave 1.4 m."""
    ego = np.array([0.0, 0.0, 0.0, 5.0])
    beside = point(0.0, 4.0, 0.0)
    discs = Scenario.preset("low", ego_radius=2.0, object_radius=2.0, severity="probability")
    bodies = Scenario.preset("low", severity="probability", **BODIES)
    assert make_estimator("worst_case", discs).risk(ego, beside) > 0
    assert make_estimator("worst_case", bodies).risk(ego, beside) == 0
    behind = point(-5.5, 0.0, 0.0)  # 0.5 m behind the ego's rear bumper: the cover reaches it
    assert make_estimator("worst_case", discs).risk(ego, behind) == 0
    assert make_estimator("worst_case", bodies).risk(ego, behind) > 0


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-8, 8),
    st.floats(-8, 8),
    st.floats(-math.pi, math.pi),
    st.floats(-math.pi, math.pi),
    st.floats(0.0, 2.0),
)
def test_the_worst_case_keeps_every_ego_disc_off_the_objects_capsule(x, y, th_e, th_o, half):
    """The largest over the ego's discs against the object's stretched box, at least the largest
    over the nine pairs of discs (the capsule holds them), and the forms agree."""
    s = Scenario.preset("low", severity="probability", **BODIES)
    est = make_estimator("worst_case", s)
    ego = np.array([x, y, th_e, 4.0])
    b = Belief(0.0, 0.0, th_o, 5.0, 0.3, 0.3, 0.1, half, 0.5 * half, 4.0, 6.0, frame=0.3)
    inner = est.inner
    capsule = stretched(b, max(s.object.disc_offsets))
    discs = [float(inner.risk(moved_ego(ego, a), capsule)) for a in s.ego.disc_offsets]
    pairs = [
        float(inner.risk(moved_ego(ego, a), moved_belief(b, c)))
        for a in s.ego.disc_offsets
        for c in s.object.disc_offsets
    ]
    assert float(est.risk(ego, b)) == pytest.approx(max(discs))
    assert max(discs) >= max(pairs)
    assert est.risk_one(tuple(ego), b) == pytest.approx(float(est.risk(ego, b)))
    distances = [float(inner.distance(moved_ego(ego, a), capsule)) for a in s.ego.disc_offsets]
    assert float(est.distance(ego, b)) == pytest.approx(min(distances))
    pair_distances = [
        float(inner.distance(moved_ego(ego, a), moved_belief(b, c)))
        for a in s.ego.disc_offsets
        for c in s.object.disc_offsets
    ]
    assert min(distances) <= min(pair_distances) + 1e-9
    X = ca.SX.sym("x", 4)
    margin = ca.Function("m", [X], [est.casadi_margin(X, b, 0.5)])
    assert (float(margin(ego)) >= 0) == (float(est.risk(ego, b)) <= 0.5)


def test_the_capsules_box_holds_the_segment_of_centres():
    """Every centre of the object's discs, and every point between them, lies in the stretched box
    of every centre the belief allows (its corners here), in the belief's frame."""
    b = Belief(1.0, -2.0, 0.7, 5.0, 0.3, 0.3, 0.1, 1.5, 0.4, 4.0, 6.0, frame=0.2)
    box = stretched(b, 2.0)
    for cx, cy in [(-1, -1), (-1, 1), (1, -1), (1, 1)]:
        along, across = cx * b.half_x, cy * b.half_y  # a corner of the centres' box, in the frame
        for t in np.linspace(-2.0, 2.0, 9):
            dx = along + t * math.cos(b.theta - b.frame)
            dy = across + t * math.sin(b.theta - b.frame)
            assert abs(dx) <= box.half_x + 1e-12 and abs(dy) <= box.half_y + 1e-12


def touching_share(s: Scenario, ego: np.ndarray, b: Belief, draws: np.ndarray) -> float:
    """The share of the object's sampled centres ``draws (J, 2)`` at which some pair of discs touches."""
    hits = np.zeros(len(draws), bool)
    for a in s.ego.disc_offsets:
        e = moved_ego(ego, a)
        for c in s.object.disc_offsets:
            centre = draws + c * np.array([math.cos(b.theta), math.sin(b.theta)])
            hits |= np.hypot(centre[:, 0] - e[0], centre[:, 1] - e[1]) <= s.collision_distance
    return float(hits.mean())


@pytest.mark.parametrize("name", ["exact", "monte_carlo"])
def test_the_expected_risk_bounds_the_bodies_chance_of_touching(name):
    """The exact form's capsule box and Monte Carlo's pairs are at least the chance that any pair
    touches (sampled: random poses, frames off the heading), and the numpy, scalar and CasADi
    forms give the same number."""
    s = Scenario.preset("low", severity="probability", mc_samples=4000, **BODIES)
    est = make_estimator(name, s)
    rng = np.random.default_rng(0)
    for _ in range(12):
        theta, frame = rng.uniform(-math.pi, math.pi, 2)
        sigma, half = rng.uniform(0.2, 2.0), rng.uniform(0.3, 4.0)
        b = Belief(0.0, 0.0, theta, 5.0, sigma, 0.6 * sigma, 0.1, half, 0.7 * half, 4.0, 6.0, frame=frame)
        ego = np.array([*rng.uniform(-7, 7, 2), rng.uniform(-math.pi, math.pi), 5.0])
        share = touching_share(s, ego, b, b.sample(rng, 20000)[:, :2])
        bound = float(est.risk(ego, b, rng=np.random.default_rng(1)))
        noise = 4 * math.sqrt(max(share * (1 - share), 1e-6) / (4000 if name == "monte_carlo" else 20000))
        assert bound >= share - noise - 1e-9
    if name == "monte_carlo":
        return
    b = point(0.0, 0.0, 0.4, half=2.0, sigma=1.0)
    X = ca.SX.sym("x", 4)
    f = ca.Function("r", [X], [est.casadi_risk(X, b)])
    draws = b.sample(rng, 20000)[:, :2]
    for ego in ([3.0, 2.0, 1.2, 5.0], [0.0, 4.5, 0.0, 5.0], [6.0, -1.0, -0.5, 5.0]):
        ego = np.array(ego)
        share = touching_share(s, ego, b, draws)
        bound = float(est.risk(ego, b))
        assert bound >= share - 4 * math.sqrt(share * (1 - share) / len(draws)) - 1e-9
        assert float(est.solver_risk(ca.DM(ego), b)) == pytest.approx(bound, rel=1e-9, abs=1e-12)
        assert float(f(ego)) == pytest.approx(bound, rel=1e-9, abs=1e-12)
        assert est.risk_one(tuple(ego), b) == pytest.approx(bound, rel=1e-9, abs=1e-12)
    assert float(est.risk(np.array([3.0, 2.0, 1.2, 5.0]), b)) > 0


def test_the_solvers_key_holds_the_objects_discs():
    from agents.mpc.nlp.ocp import problem_key

    assert problem_key(Scenario.preset("low")) != problem_key(
        Scenario.preset("low", object_discs=3, object_length=5.0)
    )


def test_the_gate_reaches_along_the_lane_to_the_outer_discs():
    pytest.importorskip("highway_env")
    from risk_env.highway import make_intersection_env
    from risk_env.highway.gate import make_gate

    env = make_intersection_env()
    env.reset(seed=0)
    one, _ = make_gate(True, None, Scenario.preset("low", ego_radius=2.0, object_radius=2.0), env)
    car, _ = make_gate(True, None, Scenario.preset("low", **BODIES), env)
    assert one.reach == pytest.approx(4.0)
    assert car.reach == pytest.approx(2 * (CAR["radius"] + 5.0 / 3))


def test_the_command_builds_cars_of_discs_and_refuses_a_radius_beside_them():
    pytest.importorskip("highway_env")
    from benchmarks import highway_intersection
    from benchmarks.highway_agents import body_overrides

    args = highway_intersection.parse_args(["--car-discs", "3"])
    overrides = body_overrides(args)
    assert overrides["ego_discs"] == overrides["object_discs"] == 3
    assert overrides["object_radius"] == pytest.approx(1.3017, abs=1e-4)
    assert body_overrides(highway_intersection.parse_args([])) == {"object_radius": 2.0}
    with pytest.raises(ValueError, match="--object-radius"):
        body_overrides(highway_intersection.parse_args(["--car-discs", "3", "--object-radius", "1"]))


def test_the_exact_bodies_box_is_cheaper_for_the_solver_than_one_disc():
    """The capsules' box replaced the nine pairs' quadratures, whose Hessian made the SMPC's NLP too
    large to build: one row's Hessian is smaller than one disc's, the pairs' eleven times it."""
    one = make_estimator("exact", Scenario.preset("low", severity="probability"))
    bodies = make_estimator("exact", Scenario.preset("low", severity="probability", **BODIES))
    x, q = ca.SX.sym("x", 4), ca.SX.sym("b", Belief.SIZE)

    def hessian_nodes(risk: ca.SX) -> int:
        return ca.Function("h", [x, q], [ca.hessian(risk, x)[0]]).n_nodes()

    b = Belief.from_array(q)
    disc = hessian_nodes(one.solver_risk(x, b))
    assert hessian_nodes(bodies.solver_risk(x, b)) < disc
    pairs = sum(bodies.inner.solver_risk(e, m) for e, m, _ in bodies.pairs(x, b))
    assert hessian_nodes(pairs) > 8 * disc


@pytest.mark.parametrize("kind", ["rmpc", "smpc"])
def test_the_planners_keep_their_promise_for_bodies_of_discs(kind):
    """The paper's scene with both vehicles as three 1 m discs along 4 m: the RMPC's plans keep
    every pair of discs off every truncation box, the SMPC's keep the bodies' bound within its
    tolerance, and the env scores the bodies (its risk of the step taken within the plan's)."""
    body = {"discs": 3, "length": 4.0, "radius": 1.0}
    overrides = {f"{who}_{k}": v for who in ("ego", "object") for k, v in body.items()}
    epsilon = 0.01
    scenario = Scenario.preset("medium", severity="probability", risk_tolerance=epsilon, **overrides)
    estimator = "worst_case" if kind == "rmpc" else "exact"
    env = gym.make("RiskCrossing-v0", scenario=scenario, risk_estimator=estimator)
    make = RMPC if kind == "rmpc" else SMPC
    agent = make.from_env(env, max_solve_time=math.inf)
    assert isinstance(agent.estimator, BodyRisk)
    obs, _ = env.reset(seed=0)
    nearest = np.inf
    for _ in range(12):
        action, _ = agent.predict(obs)
        report = agent.last_solve
        assert report.success and report.fallback is None
        beliefs = predict_array(scenario, ob.split(obs).object_measurement)[1:]
        if kind == "rmpc":
            worst = make_estimator("worst_case", scenario)
            ego = np.column_stack([report.ego_trajectory[1:], report.inputs[:, 0]])  # pose n, v_{n-1}
            clearance = worst.distance(ego, beliefs) - worst.radius
            assert np.all(clearance >= -1e-3), clearance
            nearest = min(nearest, float(clearance.min()))
        else:
            assert np.all(report.risk <= epsilon + 1e-6), report.risk
        obs, _, terminated, _, info = env.step(action)
        assert info["risk"] <= (0.0 if kind == "rmpc" else epsilon) + 1e-6
        assert not terminated
        if kind == "smpc":
            nearest = min(nearest, float(np.max(report.risk)))
    # the rows bind: the RMPC's plans touch a box, the SMPC's use its tolerance
    assert nearest < 0.05 if kind == "rmpc" else nearest > 0.2 * epsilon


def test_monte_carlo_draws_move_with_the_objects_discs_at_every_step():
    """Draws ``(J, N, 3)`` against beliefs of N steps (the SMPC's numpy risk): each object disc's
    draws are the centre's moved along that step's heading, and the risk sums the pairs."""
    s = Scenario.preset("low", severity="probability", **BODIES)
    est = make_estimator("monte_carlo", s)
    theta = np.array([0.0, 0.5, 1.0])
    b = Belief(
        np.zeros(3),
        np.zeros(3),
        theta,
        np.full(3, 5.0),
        *(np.full(3, x) for x in (1.0, 0.5, 0.1, 2.0, 1.0)),
        np.full(3, 4.0),
        np.full(3, 6.0),
        frame=theta,
    )
    draws = b.sample(np.random.default_rng(0), 50)  # (J, N, 3)
    moved = moved_draws(draws, 2.0, theta)
    assert np.allclose(moved[..., 0] - draws[..., 0], 2.0 * np.cos(theta))
    assert np.allclose(moved[..., 1] - draws[..., 1], 2.0 * np.sin(theta))
    ego = np.array([[1.0, 2.0, 0.3, 5.0]] * 3)
    pairs = sum(
        est.inner.risk(moved_ego(ego, a), moved_belief(b, c), draws=moved_draws(draws, c, theta))
        for a in s.ego.disc_offsets
        for c in s.object.disc_offsets
    )
    assert np.allclose(est.risk(ego, b, draws=draws), pairs)
    assert pairs.max() > 0


def exact_and_worst(epsilon: float = 0.025) -> tuple[Scenario, BodyRisk, BodyRisk]:
    s = Scenario.preset("low", severity="probability", risk_tolerance=epsilon, **BODIES)
    return s, make_estimator("exact", s), make_estimator("worst_case", s)


def smpc_row(exact: BodyRisk, worst: BodyRisk, ego: np.ndarray, b: Belief, epsilon: float) -> float:
    r"""The SMPC's risk row on one object at one stage (:meth:`agents.mpc.smpc.SMPC._margin`):
    $\max(d - r, (\epsilon - R) / \mathrm{scale})$ with the worst case's clearance and the solver's $R$."""
    clearance = float(worst.distance(ego, b)) - worst.radius
    margin = (epsilon - float(exact.solver_risk(ca.DM(ego), b))) / exact.severity.scale
    return max(clearance, margin)


def test_a_car_passing_in_the_next_lane_at_an_angle_costs_nothing():
    """The exit lane of an intersection episode: the ego, turned 0.22 rad off its lane, passes a
    car in the next lane. No position the belief allows touches it (every ego disc clears the
    car's capsule by 0.16 m), yet the capsules' bounding box, widened by the ego's turn, holds a
    third of the car's mass: the charged risk is 0, not the box's 0.32, and the SMPC's row, met by
    the clearance, keeps its promise R <= epsilon."""
    _, exact, worst = exact_and_worst()
    ego = np.array([-31.063, -1.061, 2.919, 6.652])
    b = Belief(-27.235, 2.0, 0.0, 5.857, 0.371, 0.2, 1.25, 1.118, 0.5, 4.243, 7.871, frame=0.0)
    assert float(exact.capsule_clearance(ego, b)) == pytest.approx(0.162, abs=1e-3)
    assert float(exact.capsule_clearance(ego, b)) == pytest.approx(
        float(worst.distance(ego, b)) - worst.radius
    )
    assert float(exact._boxed(ego, b, NUMPY, gated=False)) > 0.3
    assert float(exact.solver_risk(ca.DM(ego), b)) > 0.3  # the solver's smooth bound stays the box's
    assert float(exact.risk(ego, b)) == 0.0 and exact.risk_one(tuple(ego), b) == 0.0
    X = ca.SX.sym("x", 4)
    assert float(ca.Function("r", [X], [exact.casadi_risk(X, b)])(ego)) == 0.0
    assert smpc_row(exact, worst, ego, b, 0.025) > 0
    closer = ego + np.array([0.0, 0.5, 0.0, 0.0])  # 0.5 m nearer: the discs may touch, the box counts
    assert float(exact.capsule_clearance(closer, b)) < 0
    assert float(exact.risk(closer, b)) == pytest.approx(float(exact._boxed(closer, b, NUMPY, gated=False)))
    assert float(exact.risk(closer, b)) > 0.3


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-9, 9),
    st.floats(-9, 9),
    st.floats(-math.pi, math.pi),
    st.floats(-math.pi, math.pi),
    st.floats(-math.pi, math.pi),
    st.floats(0.05, 2.0),
    st.floats(0.0, 0.5),
)
def test_the_smpcs_row_keeps_the_charged_risk_within_its_tolerance(x, y, th_e, th_o, frame, half, epsilon):
    """Wherever the SMPC's row holds, the risk it is charged (the env's and the agent's numpy, scalar
    and CasADi forms alike) is at most epsilon; the estimator's margin is the same row; the risk is 0
    wherever the worst case's clearance is positive, and is the capsules' box elsewhere."""
    _, exact, worst = exact_and_worst()
    ego = np.array([x, y, th_e, 5.0])
    b = Belief(0.0, 0.0, th_o, 5.0, 0.4, 0.3, 1.0, half, 0.6 * half, 4.0, 6.0, frame=frame)
    risk = float(exact.risk(ego, b))
    assert exact.risk_one(tuple(ego), b) == pytest.approx(risk, rel=1e-9, abs=1e-12)
    X = ca.SX.sym("x", 4)
    assert float(ca.Function("r", [X], [exact.casadi_risk(X, b)])(ego)) == pytest.approx(
        risk, rel=1e-9, abs=1e-12
    )
    row = smpc_row(exact, worst, ego, b, epsilon)
    if row >= 0:
        assert risk <= epsilon + 1e-12
    margin = float(ca.Function("m", [X], [exact.casadi_margin(X, b, epsilon)])(ego))
    assert margin == pytest.approx(row, rel=1e-9, abs=1e-9)
    clearance = float(worst.distance(ego, b)) - worst.radius
    if clearance > 0:
        assert risk == 0.0
    else:
        assert risk == pytest.approx(float(exact.solver_risk(ca.DM(ego), b)), rel=1e-9, abs=1e-15)
