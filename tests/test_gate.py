"""The junction gate (risk_env.highway.gate): it closes when a vehicle's predicted bound occupies a
point of the junction's conflict zone while the ego would be there, opens otherwise, never after the ego
commits; its virtual object is neither scored (RiskCostWrapper) nor charged to an SMPC's budget."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from risk_env.highway.gate import (
    HOLD_GAP,
    LINE_BUFFER,
    VIRTUAL_HALF,
    GateError,
    GatePredictor,
    JunctionGate,
    check_gate,
    junction_span,
    standing,
    travel_time,
)
from risk_env.highway.route import RoutePath
from risk_env.prediction.belief import Belief
from risk_env.prediction.mixture import Mixture
from risk_env.prediction.predictors import Predictor
from risk_env.risk.estimators import make_estimator
from risk_env.scenario.scenario import Pose, ReferencePath, Scenario

DT = 0.5
# a straight route along +x: the approach (0..50 m), the junction (50..70 m), the exit
ROUTE = RoutePath(
    lanes=(("o0", "ir0", 0), ("ir0", "il1", 0), ("il1", "o1", 0)),
    paths=tuple(
        ReferencePath(goal=Pose(end, 0.0, 0.0), curvature=0.0, lambda_start=-length)
        for end, length in ((50.0, 50.0), (70.0, 20.0), (120.0, 50.0))
    ),
)


class Crossing(Predictor):
    """Each road user drives on at its measured heading and speed; its box grows by ``growth``
    [m] per second along its heading (a bound on how far ahead it may be)."""

    name = "crossing"
    max_modes = 1

    def __init__(self, growth: float = 0.0) -> None:
        self.growth = growth
        self.calls = 0

    def predict(self, measurement, steps):
        self.calls += 1
        x, y, th, v, _ = (float(c) for c in measurement)
        t = np.arange(steps + 1) * DT
        full = lambda value: np.full(steps + 1, float(value))  # noqa: E731
        belief = Belief(
            x=x + v * t * math.cos(th), y=y + v * t * math.sin(th), theta=full(th), speed=full(v),
            sigma_x=0.1 + 0.5 * self.growth * t, sigma_y=full(0.1), sigma_v=full(0.1),
            half_x=0.3 + self.growth * t, half_y=full(1.0), v_lo=full(0.0), v_hi=full(v + 1.0),
            frame=full(th),
        )  # fmt: skip
        return Mixture.single(belief)


def gate(predictor: Predictor | None = None, speed_cap: float = 8.0) -> JunctionGate:
    g = JunctionGate(predictor or Crossing(), reach=4.0, accel=3.0, half_length=2.5, dt=DT)
    g.reset(ROUTE, Scenario.preset("low", v_ref=speed_cap, v_max=10.0, v_min=0.0))
    return g


def crossing_at(x: float, y0: float, speed: float) -> np.ndarray:
    """A vehicle at (x, y0) driving toward +y (across the route) at ``speed``."""
    return np.array([[x, y0, math.pi / 2, speed, 0.0]])


def test_the_conflict_zone_is_the_routes_junction_lanes():
    assert junction_span(ROUTE) == (50.0, 70.0)
    outside = RoutePath(lanes=(("o0", "o1", 0),), paths=(ROUTE.paths[0],))
    assert junction_span(outside) is None


def test_travel_time_accelerates_to_the_cap():
    assert travel_time(np.array([0.0, -1.0]), 5.0, 3.0, 8.0).tolist() == [0.0, 0.0]
    # from rest: 1.5 t^2 = 6 m in 2 s; then 8 m/s after 32/6 m
    assert travel_time(np.array([6.0]), 0.0, 3.0, 8.0)[0] == pytest.approx(2.0)
    d_acc = 64.0 / 6.0
    assert travel_time(np.array([d_acc + 16.0]), 0.0, 3.0, 8.0)[0] == pytest.approx(8.0 / 3.0 + 2.0)


def test_the_gate_closes_for_a_vehicle_that_reaches_the_zone_while_the_ego_is_in_it():
    g = gate()
    # at the route's x = 60 from 2.6 to 3.4 s; the ego (from 30 m at 5 m/s) there from 3.0 to 3.4 s
    decision = g.decide(30.0, 5.0, crossing_at(60.0, -30.0, 10.0))
    assert decision.closed and not decision.committed and decision.slack < 0.0
    virtual = g.virtual()
    # on the route, the ego's front stopping LINE_BUFFER before the line: centre + half length = 48.5
    assert virtual[1] == 0.0 and virtual[3] == 0.0 and virtual[0] - 4.0 + 2.5 == 50.0 - LINE_BUFFER
    assert g.closed_steps == 1


def test_the_gate_opens_when_nobody_comes_in_time():
    g = gate()
    assert not g.decide(30.0, 5.0, crossing_at(60.0, -300.0, 10.0)).closed  # 30 s away
    assert not g.decide(30.0, 5.0, np.zeros((0, 5))).closed
    # the same vehicle, its bound growing ahead of it: now it may come in time
    growing = gate(Crossing(growth=30.0))
    assert growing.decide(30.0, 5.0, crossing_at(60.0, -80.0, 10.0)).closed
    assert not gate().decide(30.0, 5.0, crossing_at(60.0, -80.0, 10.0)).closed
    # a vehicle that crosses the zone after the ego has cleared it is no conflict
    assert not gate().decide(44.0, 8.0, crossing_at(55.0, -60.0, 10.0)).closed
    # far from the junction the gate does not judge
    assert not gate().decide(-20.0, 5.0, crossing_at(60.0, -20.0, 10.0)).closed


def test_a_vehicle_that_has_left_a_point_before_the_ego_comes_is_no_conflict():
    """Judged by occupancy, not by arrival: the gate once closed for every vehicle that reached a
    point of the zone before the ego had cleared it, also one that had left it long before the ego
    came (a leader on the ego's own route, a car crossing now)."""
    assert not gate().decide(20.0, 5.0, crossing_at(60.0, -3.0, 10.0)).closed  # gone in under 1 s
    leader = np.array([[55.0, 0.0, 0.0, 8.0, 0.0]])  # ahead on the route, driving on
    assert not gate().decide(20.0, 5.0, leader).closed
    stopped = np.array([[60.0, 0.0, 0.0, 0.0, 0.0]])  # stands in the zone: still there when the ego comes
    assert gate().decide(20.0, 5.0, stopped).closed
    # its box growing behind it too (it may be slower): the point may still be occupied
    assert gate(Crossing(growth=30.0)).decide(20.0, 5.0, crossing_at(60.0, -3.0, 10.0)).closed


def test_the_gate_never_closes_after_the_ego_commits():
    g = gate()
    assert not g.decide(45.0, 8.0, crossing_at(60.0, -200.0, 10.0)).closed
    # open, and it cannot stop before the line any more (8^2 / 6 > 2.5 m left): committed
    decision = g.decide(45.0, 8.0, crossing_at(60.0, -20.0, 10.0))
    assert decision.committed and not decision.closed
    assert not g.decide(47.0, 2.0, crossing_at(60.0, -5.0, 10.0)).closed
    # a gate that closed while the ego could stop stays closed when it can no longer (no commit)
    h = gate()
    assert h.decide(30.0, 8.0, crossing_at(60.0, -25.0, 10.0)).closed
    late = h.decide(45.0, 8.0, crossing_at(60.0, -15.0, 10.0))
    assert late.closed and not late.committed
    # an ego stopped past the line is held: the virtual object just ahead of its disc, staying there
    assert h.decide(49.0, 0.0, crossing_at(60.0, -25.0, 10.0)).closed
    held = h.virtual()[0]
    assert held == pytest.approx(49.0 + 4.0 + VIRTUAL_HALF + HOLD_GAP)
    assert h.decide(49.0, 0.0, crossing_at(60.0, -25.0, 10.0)).closed and h.virtual()[0] == held
    # an ego that crept on into it moves it no further than its disc: no new gap to creep into
    late = h.decide(52.0, 0.0, crossing_at(60.0, -25.0, 10.0))
    assert late.closed and not late.committed and h.virtual()[0] == pytest.approx(52.0 + 4.0 + VIRTUAL_HALF)
    assert h.decide(52.0, 0.0, crossing_at(60.0, -25.0, 10.0)).closed
    assert h.virtual()[0] == pytest.approx(52.0 + 4.0 + VIRTUAL_HALF)


def test_the_gate_predictor_keeps_the_virtual_object_out_of_the_scene():
    inner = Crossing()
    wrapped = GatePredictor(inner)
    g = gate()
    g.decide(30.0, 5.0, crossing_at(60.0, -20.0, 10.0))
    wrapped.virtual = g.virtual()
    rows = np.vstack([wrapped.virtual.astype(np.float32), crossing_at(60.0, -20.0, 10.0)])
    inner.calls = 0
    mixtures = wrapped.predict_scene(rows, 6)
    assert inner.calls == 1 and len(mixtures) == 2  # the virtual row never reaches the inner predictor
    stand = mixtures[0].modes[0].beliefs
    assert np.all(stand.x == stand.x[0]) and np.all(stand.speed == 0.0)
    wrapped.virtual = None
    assert inner.calls == 1 and len(wrapped.predict_scene(rows, 6)) == 2 and inner.calls == 3


def test_the_virtual_objects_risk_is_zero_off_its_disc():
    """An SMPC is charged its exact risk of the applied step: 0 for the virtual object whenever the
    ego's disc keeps VIRTUAL_HALF clear of it (the risk of a truncated belief outside its box)."""
    scenario = Scenario.preset(
        "low", ego_radius=2.0, object_radius=2.0, v_max=10.0, v_min=0.0, v_ref=8.0, severity="probability"
    )
    belief = standing(np.array([10.0, 0.0, 0.0, 0.0, 0.0]), 1).modes[0].at(1)
    estimator = make_estimator("exact", scenario)
    clear = 10.0 - 4.0 - VIRTUAL_HALF - 0.05
    assert float(estimator.risk(np.array([clear, 0.0, 0.0, 5.0]), belief)) == 0.0
    assert float(estimator.risk(np.array([10.0 - 3.0, 0.0, 0.0, 5.0]), belief)) > 0.9


def test_the_virtual_objects_risk_is_given_back_to_the_budget():
    """An SMPC charges its budget the whole risk of the applied step (report.risk_fn, over every
    slot's rows); the gate gives back the virtual object's share (row 0) when it was closed."""

    def risk(ego_states, futures, data):  # the RiskFunction: summed over the present rows
        return np.array([sum({"virtual": 0.7, "car": 0.2}[f] for f in futures if f is not None)])

    class Report:
        risk_fn = functools.partial(risk, np.zeros((6, 4)), ["virtual", None, None, "car"], None)

    class Budgeted:  # SMPC's budget API: spent_risk and refund
        risk_budget = 0.05

        def __init__(self):
            self._spent = {0: 0.9 + 0.5}  # this step's 0.9, 0.5 before

        def spent_risk(self, index: int = 0) -> float:
            return self._spent[index]

        def refund(self, risk: float, index: int = 0) -> None:
            self._spent[index] -= risk

    g, agent = gate(), Budgeted()
    assert g.decide(30.0, 5.0, crossing_at(60.0, -30.0, 10.0)).closed
    assert g.refund(agent, Report()) == pytest.approx(0.7)
    assert agent._spent[0] == pytest.approx(0.7) and g.refunded == pytest.approx(0.7)
    g.decide(30.0, 5.0, crossing_at(60.0, -300.0, 10.0))  # open: nothing virtual to give back
    assert g.refund(agent, Report()) == 0.0 and agent._spent[0] == pytest.approx(0.7)
    no_budget = Budgeted()
    no_budget.risk_budget = None
    assert g.decide(30.0, 5.0, crossing_at(60.0, -30.0, 10.0)).closed
    assert g.refund(no_budget, Report()) == 0.0


def test_bad_values_are_named():
    with pytest.raises(GateError, match="gate must be True, False"):
        check_gate("yes")
    with pytest.raises(GateError, match="accel"):
        JunctionGate(Crossing(), reach=4.0, accel=0.0, half_length=2.5, dt=DT)
    with pytest.raises(GateError, match="margin"):
        JunctionGate(Crossing(), reach=4.0, accel=3.0, half_length=2.5, dt=DT, margin=-1.0)
    with pytest.raises(GateError, match="threshold"):
        JunctionGate(Crossing(), reach=4.0, accel=3.0, half_length=2.5, dt=DT, threshold=2.0)
    for share in (0.0, 1.5, math.nan):
        with pytest.raises(GateError, match="approach_braking"):
            JunctionGate(Crossing(), reach=4.0, accel=3.0, half_length=2.5, dt=DT, approach_braking=share)
    with pytest.raises(GateError, match="inner must be a Predictor"):
        GatePredictor("lane")
    assert issubclass(GateError, ValueError)


def test_the_adapter_plans_against_the_virtual_object_which_is_not_scored():
    """With the gate forced shut, slot 0 of every observation before the junction is the virtual
    object; the scored risk (RiskCostWrapper, the env's own vehicles) is the same as without it."""
    pytest.importorskip("highway_env")
    from risk_env import observation as layout
    from risk_env.highway import IntersectionAdapter, RiskCostWrapper, make_intersection_env

    seen: list[np.ndarray] = []

    class Stub:
        def __init__(self, scenario, object_slots, predictor=None):
            self.predictor = predictor

        def predict(self, obs, episode_start=None, deterministic=True):
            seen.append(np.asarray(obs))
            return np.array([6.0, 0.0]), None

    risks = {}
    for on in (True, False):
        env = RiskCostWrapper(make_intersection_env(), estimator="exact", ego_radius=2.0, object_radius=2.0)
        adapter = IntersectionAdapter(env, Stub, slots=3, gate=on)
        obs, _ = env.reset(seed=3)
        adapter.reset()
        if on:
            adapter.gate.margin = 1e9  # shut whenever it judges
        seen.clear()
        risks[on] = []
        for _ in range(6):
            action, _ = adapter.predict(obs)
            obs, _, terminated, truncated, info = env.step(action)
            risks[on].append(info["risk"])
            if terminated or truncated:
                break
        first = np.asarray(seen[-1])[layout.EGO_SIZE : layout.EGO_SIZE + layout.SLOT_SIZE]
        if on:
            assert adapter.gate.closed_steps > 0 and isinstance(adapter.gate.wrapper, GatePredictor)
            assert first[0] == 1.0 and first[4] == 0.0  # present, speed 0: the virtual object
            np.testing.assert_allclose(first[1:], adapter.gate.virtual(), atol=1e-3)
            assert len(adapter.last_objects) <= 2  # the real vehicles: one slot fewer
            assert not np.any(np.all(np.abs(adapter.last_objects - adapter.gate.virtual()) < 1e-3, axis=1))
        else:
            assert adapter.gate is None
    assert risks[True] == risks[False]
    with pytest.raises(GateError, match="gate must be True, False"):
        IntersectionAdapter(env, Stub, gate="on")


class SpeedStub:
    """A lane agent that asks for ``speed`` [m/s] straight on and records the speed limits it is handed."""

    speed = 6.0

    def __init__(self, scenario, object_slots, predictor=None):
        self.speed_limit, self.limits = math.inf, []

    def predict(self, obs, episode_start=None, deterministic=True):
        self.limits.append(self.speed_limit)
        return np.array([self.speed, 0.0]), None


def shut_gate(settings, make_agent):
    """``(env, adapter, first observation)``: an intersection episode (seed 3) whose adapter, gated by
    ``settings``, drives ``make_agent``'s agents with a gate that shuts whenever it judges."""
    from risk_env.highway import IntersectionAdapter, make_intersection_env

    env = make_intersection_env()
    adapter = IntersectionAdapter(env, make_agent, slots=3, gate=settings)
    obs, _ = env.reset(seed=3)
    adapter.reset()
    adapter.gate.margin = 1e9
    return env, adapter, obs


def test_a_slow_approach_reaches_the_agents_speed_limit_and_the_command():
    """With the gate shut and ``slow_approach``, each step the adapter hands the lane's agent the
    gate's stop speed, which falls as the ego comes on; without the switch, no cap."""
    pytest.importorskip("highway_env")
    from benchmarks import highway_intersection
    from benchmarks.highway_agents import gate_settings
    from risk_env.highway.gate_judge import GateSettings

    for slow in (True, False):
        env, adapter, obs = shut_gate(GateSettings(slow_approach=slow), SpeedStub)
        for _ in range(4):
            obs, *_ = env.step(adapter.predict(obs)[0])
        limits = adapter._agent_for(adapter.lane).limits
        if slow:
            assert all(math.isfinite(v) for v in limits) and limits == sorted(limits, reverse=True)
        else:
            assert limits == [math.inf] * 4
    assert gate_settings(highway_intersection.parse_args(["--gate-slow-approach"])).slow_approach
    assert not gate_settings(highway_intersection.parse_args([])).slow_approach


def test_the_commands_gate_option_reaches_the_adapter():
    pytest.importorskip("highway_env")
    from benchmarks import highway_frontier, highway_intersection
    from benchmarks.highway_agents import make_driver, resolve
    from risk_env.highway import make_intersection_env

    assert highway_intersection.parse_args([]).gate is True
    assert highway_frontier.parse_args(["--no-gate"]).gate is False
    env = make_intersection_env()
    for flag, on in (("--gate", True), ("--no-gate", False)):
        args = highway_intersection.parse_args([flag])
        driver = make_driver(resolve("rmpc", args.severity, args.budget), env, args, "lane")
        assert (driver._gate_on is not None) is on  # on: the gate's settings (its defaults)


def test_the_smpc_takes_back_a_refund_within_what_it_spent():
    from agents import SMPC

    agent = SMPC(Scenario.preset("low", severity="probability"), risk_budget=0.05, max_solve_time=math.inf)
    agent._spent[0] = 0.03  # as after steps that spent 0.03
    agent.refund(0.01)
    assert agent.spent_risk() == pytest.approx(0.02)
    for bad in (-0.001, 0.5, math.nan):
        with pytest.raises(ValueError, match="risk"):
            agent.refund(bad)
    assert agent.spent_risk() == pytest.approx(0.02)


def test_a_closed_gate_slows_the_approach_so_that_the_ego_stops_at_the_line():
    """With ``slow_approach``, a closed gate asks for a speed from which half the largest braking
    stops the ego's disc at the virtual object, sqrt(a d); open, or without the switch, none.
    (Measured: without it the MPC, whose 3 s horizon has no terminal row, came on at its reference
    speed until it could no longer stop, and stood in the junction.)"""
    g = gate()
    g.slow_approach = True
    assert g.stop_speed() == math.inf  # nothing judged yet
    g.step(30.0, 5.0, crossing_at(60.0, -30.0, 10.0))
    assert g.last.closed
    stop = g.virtual()[0] - VIRTUAL_HALF - 4.0  # where the ego's centre must stop
    assert g.stop_speed() == pytest.approx(math.sqrt(3.0 * (stop - 30.0)))
    g.step(stop - 1.0, 2.0, crossing_at(60.0, -30.0, 10.0))
    assert g.stop_speed() == pytest.approx(math.sqrt(3.0))
    g.step(stop + 0.5, 0.0, crossing_at(60.0, -30.0, 10.0))  # past it: held just ahead, stand
    assert g.last.closed and g.stop_speed() == pytest.approx(math.sqrt(3.0 * HOLD_GAP))
    g.step(stop + 1.2, 0.5, crossing_at(60.0, -30.0, 10.0))  # crept into it: no room left, stand
    assert g.last.closed and g.stop_speed() == 0.0
    assert not g.decide(20.0, 5.0, crossing_at(60.0, -300.0, 10.0)).closed
    assert g.stop_speed() == math.inf
    plain = gate()  # the switch off: never a cap
    plain.step(30.0, 5.0, crossing_at(60.0, -30.0, 10.0))
    assert plain.last.closed and plain.stop_speed() == math.inf


def test_a_hard_stop_clips_the_applied_speed_at_the_line():
    """With ``hard_stop``, a closed gate clips the speed the adapter applies at the slow approach's
    sqrt(a d), whatever the agent chose (0 once the ego's disc has crept into the virtual object);
    open, or without the switch, the agent's speed passes."""
    g = gate()
    g.hard_stop = True
    assert g.allowed_speed(6.0) == 6.0  # nothing judged yet
    g.step(30.0, 5.0, crossing_at(60.0, -30.0, 10.0))
    stop = g.virtual()[0] - VIRTUAL_HALF - 4.0
    assert g.last.closed and g.allowed_speed(9.0) == pytest.approx(math.sqrt(3.0 * (stop - 30.0)))
    assert g.allowed_speed(1.0) == 1.0  # slower than the clip: passes
    assert g.stop_speed() == math.inf  # the reference speed is slow_approach's business
    g.step(stop + 0.5, 0.0, crossing_at(60.0, -30.0, 10.0))
    g.step(stop + 1.2, 0.5, crossing_at(60.0, -30.0, 10.0))  # crept into it: stand
    assert g.last.closed and g.allowed_speed(3.0) == 0.0
    assert not g.decide(20.0, 5.0, crossing_at(60.0, -300.0, 10.0)).closed
    assert g.allowed_speed(6.0) == 6.0
    plain = gate()
    plain.step(30.0, 5.0, crossing_at(60.0, -30.0, 10.0))
    assert plain.last.closed and plain.allowed_speed(9.0) == 9.0


def test_the_approach_braking_share_sets_the_lines_speed():
    """``approach_braking`` b: the slow approach's and the hard stop's speed is sqrt(2 b a d), so the
    default 0.5 keeps sqrt(a d) and 1 (the latest full stop) is sqrt(2) times faster."""
    speeds = {}
    for share in (0.5, 1.0):
        g = gate()
        g.hard_stop = g.slow_approach = True
        g.approach_braking = share
        g.step(30.0, 5.0, crossing_at(60.0, -30.0, 10.0))
        stop = g.virtual()[0] - VIRTUAL_HALF - 4.0
        assert g.last.closed and g.stop_speed() == g.allowed_speed(99.0)
        speeds[share] = g.stop_speed()
    assert speeds[0.5] == pytest.approx(math.sqrt(3.0 * (stop - 30.0)))
    assert speeds[1.0] == pytest.approx(math.sqrt(2.0) * speeds[0.5])


def test_the_adapter_applies_the_hard_stops_speed():
    """The adapter clips the agent's speed by the gate (``--gate-hard-stop``): the same agent asking
    for full speed toward a shut gate gets a lower acceleration with the switch than without."""
    pytest.importorskip("highway_env")
    from benchmarks import highway_intersection
    from benchmarks.highway_agents import gate_settings
    from risk_env.highway.gate_judge import GateSettings

    class FullSpeed(SpeedStub):
        speed = 10.0

    commands = {}
    for hard in (True, False):
        env, adapter, obs = shut_gate(GateSettings(hard_stop=hard), FullSpeed)
        commands[hard] = []
        for _ in range(3):
            action = adapter.predict(obs)[0]
            commands[hard].append(float(action[0]))
            assert adapter.gate.last.closed
            obs, *_ = env.step(action)
    assert all(h < p for h, p in zip(commands[True], commands[False], strict=True))
    assert gate_settings(highway_intersection.parse_args(["--gate-hard-stop"])).hard_stop
    assert not gate_settings(highway_intersection.parse_args([])).hard_stop
    assert gate_settings(highway_intersection.parse_args([])).approach_braking == 0.5
    args = highway_intersection.parse_args(["--gate-hard-stop", "--gate-approach-braking", "1"])
    assert gate_settings(args).approach_braking == 1.0
