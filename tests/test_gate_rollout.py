"""The junction gate's ``"rollout"`` judge: the scene rolled out with the ego going now
(:mod:`risk_env.highway.lanes.rollout`), an ego that brakes for its leader in the speed model, and
bad input."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("highway_env")

from highway_env.road.road import RoadNetwork  # noqa: E402
from highway_helpers import LEFT_TURN, measurement  # noqa: E402

from risk_env.highway import LanePredictor, make_intersection_env  # noqa: E402
from risk_env.highway.gate import GateError, JunctionGate, junction_span  # noqa: E402
from risk_env.highway.lanes.interval import IntervalModel  # noqa: E402
from risk_env.highway.lanes.predictor import EgoPlan  # noqa: E402
from risk_env.highway.lanes.rollout import RolloutModel, roll_out  # noqa: E402
from risk_env.highway.lanes.routes import Route  # noqa: E402
from risk_env.highway.lanes.speed import Agents, SpeedModel, TrafficModel  # noqa: E402
from risk_env.highway.route import RoutePath  # noqa: E402
from risk_env.prediction.predictors import ConstantPredictor  # noqa: E402
from risk_env.scenario.scenario import Scenario  # noqa: E402

T = 0.5


def predictor_at_the_line(network):
    """The lane+interval predictor with an ego stopped 3 m before its stop line."""
    ego = measurement(network, LEFT_TURN[0], network.get_lane(LEFT_TURN[0]).length - 3.0, 0.0)
    intervals = IntervalModel(split_yield=True, centred=True)
    return LanePredictor(network, T, longitudinal="interval", intervals=intervals, ego=lambda: ego)


def test_the_ego_comes_through_an_open_junction_and_not_into_a_crossing_car(network):
    predictor = predictor_at_the_line(network)
    plan = EgoPlan(LEFT_TURN, 3.0, 8.0)
    # a car on the west road, straight on across the ego's turn: far off, it passes after the ego
    far = measurement(network, ("o1", "ir1", 0), 20.0, 8.0)
    assert roll_out(predictor, far[None], plan).through
    leaving = measurement(network, ("il2", "o2", 0), 30.0, 8.0)  # on an exit, driving away
    assert roll_out(predictor, leaving[None], plan).through
    # 20 m from its line at 8 m/s it meets the ego in the junction, in some run, whoever brakes
    near = measurement(network, ("o1", "ir1", 0), 80.0, 8.0)
    verdict = roll_out(predictor, near[None], plan)
    assert not verdict.through and "road user 0 (o1>ir1>il3>o3)" in verdict.reason
    # a conflict with a route less likely than min_weight is none: its signal says it turns off
    turning = roll_out(predictor, near[None], plan, signals=[np.array([0.0, -1.0])])
    assert turning.through != verdict.through or "il3" not in turning.reason
    # a horizon too short for the ego to reach its exit: not through when it must be, and said so
    short = roll_out(predictor, far[None], plan, model=RolloutModel(horizon=2.0, waits=False))
    assert not short.through and "cannot reach the last lane of its plan" in short.reason
    short = roll_out(predictor, far[None], plan, model=RolloutModel(horizon=4.0, waits=False))
    assert not short.through and "short of its exit" in short.reason
    for horizon in (2.0, 4.0):  # else through: the horizon, not the traffic, keeps it short
        assert roll_out(predictor, far[None], plan, model=RolloutModel(horizon=horizon)).through


def test_a_road_user_off_the_road_keeps_its_speed_and_heading(network):
    """A car standing 5 m beside the ego's exit lane, off the road: it takes no part in the runs,
    but stands where it is; with bodies 2 m wider on each side the ego, passing, meets it."""
    predictor = predictor_at_the_line(network)
    plan = EgoPlan(LEFT_TURN, 3.0, 8.0)
    car = np.array([-20.0, -7.0, np.pi, 0.0, 0.0])
    assert predictor.scene(car[None], 16).hypotheses[0] is None  # off the road
    assert roll_out(predictor, car[None], plan, model=RolloutModel(past=15.0)).through
    wide = roll_out(predictor, car[None], plan, model=RolloutModel(past=15.0, clearance=2.0))
    assert not wide.through and "road user 0 (off the road)" in wide.reason


def test_the_gate_with_the_rollout_judge_opens_as_the_rollout_says(network):
    predictor = predictor_at_the_line(network)
    path = RoutePath.from_lanes(network, LEFT_TURN)
    progress = network.get_lane(LEFT_TURN[0]).length - 3.0
    verdicts = {}
    for name, s in (("far", 20.0), ("near", 80.0)):
        gate = JunctionGate(predictor, 4.0, 3.0, 2.5, T, judge="rollout", given_ego=True)
        gate.route, gate.span, gate.speed_cap = path, junction_span(path), 8.0
        car = measurement(network, ("o1", "ir1", 0), s, 8.0)
        decision = gate.decide(progress, 0.0, car[None])
        assert decision.closed == (not roll_out(predictor, car[None], EgoPlan(LEFT_TURN, 3.0, 8.0)).through)
        assert decision.slack == (-np.inf if decision.closed else np.inf)
        verdicts[name] = decision.closed
    assert verdicts == {"far": False, "near": True}
    with pytest.raises(GateError, match="rollout judge needs the lane\\+interval predictor"):
        JunctionGate(ConstantPredictor(Scenario.preset("low")), 4.0, 3.0, 2.5, T, judge="rollout")
    with pytest.raises(GateError, match="accepts no chance of a conflict"):
        JunctionGate(predictor, 4.0, 3.0, 2.5, T, judge="rollout", tolerance=0.1)
    with pytest.raises(ValueError, match="needs a lane predictor with an ego"):
        roll_out(LanePredictor(network, T), np.zeros((1, 5)), EgoPlan(LEFT_TURN, 3.0, 8.0))


def test_an_ego_that_goes_brakes_for_its_leader_when_told_to():
    road = RoadNetwork.straight_road_network(lanes=1, length=1000.0, speed_limit=10.0)
    route = Route(road, (("0", "1", 0),))
    agents = Agents(
        np.array([0, 1]),
        [route, route],
        np.array([100.0, 130.0]),  # the ego, and a car standing 30 m ahead of it
        np.zeros(2),
        np.array([8.0, 0.0]),
        np.ones(2, dtype=bool),
    )
    model = SpeedModel(road, TrafficModel())
    ego = np.array([True, False])
    runs = {
        follows: model.run(agents, 16, T, scripted=ego, script=(3.0, 8.0), script_follows=follows)[0]
        for follows in (False, True)
    }
    assert runs[False][0, -1] > 140.0  # the script alone drives through the car
    assert np.all(runs[True][0] < runs[True][1] - 5.0)  # braking as the IDM does, it stays behind


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"horizon": 0.0}, "horizon"),
        ({"past": -1.0}, "past"),
        ({"min_weight": 1.5}, "min_weight"),
        ({"target_floor": float("nan")}, "target_floor"),
        ({"samples": 0}, "samples"),
        ({"standing": -0.5}, "standing"),
    ],
)
def test_bad_rollout_numbers_are_named(bad, match):
    with pytest.raises(ValueError, match=match):
        RolloutModel(**bad)


def passage_gate(predictor, network, judge="stretch", passage=True):
    """A gate on the ego's left turn that verifies its passage (``passage``), judging by ``judge``."""
    path = RoutePath.from_lanes(network, LEFT_TURN)
    gate = JunctionGate(predictor, 4.0, 3.0, 2.5, T, judge=judge, given_ego=True, passage=passage)
    gate.route, gate.span, gate.speed_cap = path, junction_span(path), 8.0
    return gate


def test_a_verified_passage_caps_the_speed_at_the_runs_and_a_conflict_verifies_none(network):
    predictor = predictor_at_the_line(network)
    line = network.get_lane(LEFT_TURN[0]).length
    far = measurement(network, ("o1", "ir1", 0), 20.0, 8.0)[None]
    near = measurement(network, ("o1", "ir1", 0), 80.0, 8.0)[None]
    verdict = roll_out(predictor, far, EgoPlan(LEFT_TURN, 3.0, 8.0))
    # the ego stands at its line: one step at 3 m/s^2 in every run, nobody ahead of it
    assert verdict.through and verdict.speed == pytest.approx(1.5)
    assert roll_out(predictor, near, EgoPlan(LEFT_TURN, 3.0, 8.0)).speed == np.inf
    gate = passage_gate(predictor, network, judge="rollout")
    assert len(gate.step(line - 3.0, 0.0, far)) == 0 and gate.verified_speed == pytest.approx(1.5)
    assert gate.allowed_speed(5.0) == pytest.approx(1.5) and gate.stop_speed() == pytest.approx(1.5)
    assert len(gate.step(line - 3.0, 0.0, near)) == 1 and gate.verified_speed is None  # closed
    # committed (past the line), the rollout still judges each step; a conflict verifies nothing
    gate = passage_gate(predictor, network)
    assert len(gate.step(line + 1.0, 3.0, far)) == 0 and gate.last.committed
    assert gate.verified_speed == pytest.approx(1.5)
    gate.step(line + 1.0, 3.0, near)
    assert gate.verified_speed is None and gate.allowed_speed(5.0) == 5.0 and gate.stop_speed() == np.inf
    # out of the gate's range, past the junction, or without the switch: nothing verified
    s_in, s_out = gate.span
    for progress in (s_in - 2.5 - 41.0, s_out + 2.6):
        gate.step(progress, 3.0, far)
        assert gate.verified_speed is None
    gate = passage_gate(predictor, network, passage=False)
    gate.step(line - 3.0, 0.0, far)
    assert gate.verified_speed is None
    with pytest.raises(GateError, match="verified passage needs the lane\\+interval predictor"):
        JunctionGate(ConstantPredictor(Scenario.preset("low")), 4.0, 3.0, 2.5, T, passage=True)


def test_the_adapter_hands_no_road_user_to_the_agent_on_a_verified_passage():
    """Driving a few steps of seed 3 toward the junction: wherever the gate verified the passage the
    agent gets no object and the passage's speed as its limit, elsewhere the road users as before."""
    from risk_env import observation as layout
    from risk_env.highway import IntersectionAdapter
    from risk_env.highway.gate_judge import GateSettings

    class Recorder:
        def __init__(self, scenario, object_slots, predictor=None):
            self.speed_limit, self.seen = np.inf, []

        def predict(self, obs, episode_start=None, deterministic=True):
            slots = np.asarray(obs)[layout.EGO_SIZE :].reshape(-1, layout.SLOT_SIZE)
            self.seen.append((int(slots[:, 0].sum()), self.speed_limit))
            return np.array([8.0, 0.0]), None

    env = make_intersection_env()
    settings = GateSettings(judge="rollout", given_ego=True, passage=True)
    adapter = IntersectionAdapter(env, Recorder, slots=3, predictor="lane+interval", gate=settings)
    obs, _ = env.reset(seed=3)
    adapter.reset()
    verified = []
    for _ in range(8):
        obs, _, terminated, truncated, _ = env.step(adapter.predict(obs)[0])
        agent = adapter._agent_for(adapter.lane)
        objects, limit = agent.seen[-1]
        speed = adapter.gate.verified_speed
        verified.append(speed is not None)
        assert (
            (objects == 0 and limit == speed)
            if speed is not None
            else (objects > 0 or adapter.gate.last.closed)
        )
        if terminated or truncated:
            break
    assert any(verified)


def test_a_road_user_that_stands_may_stay_in_the_slow_run(network):
    """A car standing 8 m into the ego's exit (waiting, or a wreck): the slow run keeps it there, so the
    ego, which brakes behind it, is not through; a car taken to set off for the slow run's desired
    speed (``standing=0``) leaves room in time."""
    predictor = predictor_at_the_line(network)
    plan = EgoPlan(LEFT_TURN, 3.0, 8.0)
    car = measurement(network, LEFT_TURN[2], 8.0, 0.0)[None]
    verdict = roll_out(predictor, car, plan)
    assert (
        not verdict.through
        and verdict.reason.startswith("slow run")
        and "short of its exit" in verdict.reason
    )
    assert roll_out(predictor, car, plan, model=RolloutModel(standing=0.0)).through
    moving = measurement(network, LEFT_TURN[2], 8.0, 1.0)[None]  # above the threshold: it sets off
    assert roll_out(predictor, moving, plan).through


def test_an_ego_still_before_its_junction_at_the_horizons_end_is_through(network):
    """45 m before its line at 8 m/s the ego cannot reach its exit within 8 s: with nobody about it is
    through (it enters nothing it must clear), unless told to reach its exit (``waits=False``); a
    crossing car it would meet within the horizon still stops it."""
    lane = network.get_lane(LEFT_TURN[0])
    ego = measurement(network, LEFT_TURN[0], lane.length - 45.0, 8.0)
    intervals = IntervalModel(split_yield=True, centred=True)
    predictor = LanePredictor(network, T, longitudinal="interval", intervals=intervals, ego=lambda: ego)
    plan = EgoPlan(LEFT_TURN, 3.0, 8.0)
    leaving = measurement(network, ("il2", "o2", 0), 30.0, 8.0)[None]
    assert roll_out(predictor, leaving, plan).through
    short = roll_out(predictor, leaving, plan, model=RolloutModel(waits=False))
    assert not short.through and "short of its exit" in short.reason
    near = roll_out(predictor, leaving, plan, model=RolloutModel(horizon=3.0))
    assert near.through  # 3 s at 8 m/s: 24 m, still before the line
