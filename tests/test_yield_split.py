"""The lane predictor's yielding, split: the chance that a road user yields (highway-env's rule over
the routes of those it yields to), its held and free modes, the interval boxes centred on their
interval, and the prediction given what the ego will do (the junction gate's)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("highway_env")

from highway_env.road.road import RoadNetwork  # noqa: E402
from highway_helpers import measurement  # noqa: E402

from risk_env.highway import LanePredictor  # noqa: E402
from risk_env.highway.gate import JunctionGate, junction_span  # noqa: E402
from risk_env.highway.lanes.interval import IntervalModel  # noqa: E402
from risk_env.highway.lanes.predictor import EgoPlan  # noqa: E402
from risk_env.highway.lanes.routes import Route  # noqa: E402
from risk_env.highway.lanes.speed import Agents, SpeedModel, TrafficModel  # noqa: E402
from risk_env.highway.route import RoutePath  # noqa: E402

T = 0.5
STEPS = 6


def route(network, *nodes: str) -> Route:
    return Route(network, tuple((a, b, 0) for a, b in zip(nodes, nodes[1:], strict=False)))


def chance_of(network, vehicle, routes, weights, s) -> np.ndarray:
    """The ``yields`` output of one slow run (everyone a partner) of the agents given."""
    count = len(vehicle)
    agents = Agents(
        np.array(vehicle),
        routes,
        np.array(s, float),
        np.zeros(count),
        np.full(count, 8.0),
        np.ones(count, dtype=bool),
        np.array(weights, float),
    )
    out = np.zeros(count)
    SpeedModel(network, TrafficModel()).run(agents, STEPS, T, partners=np.arange(count), yields=out)
    return out


def test_the_chance_of_yielding_is_the_mass_of_the_routes_yielded_to(network):
    vertical = route(network, "o0", "ir0", "il2", "o2")  # priority 1: yields to the horizontal roads
    straight = route(network, "o1", "ir1", "il3", "o3")  # priority 3, crosses it
    right = route(network, "o1", "ir1", "il0", "o0")  # priority 3, turns away before it
    # each alone with weight 1: the straight one is yielded to, the right turn not
    assert chance_of(network, [0, 1], [vertical, straight], [1, 1], [88, 88])[0] == 1.0
    assert chance_of(network, [0, 1], [vertical, right], [1, 1], [88, 88])[0] == 0.0
    # one road user on both routes: its straight route's weight
    both = chance_of(network, [0, 1, 1], [vertical, straight, right], [1, 0.3, 0.7], [88, 88, 88])
    assert both[0] == pytest.approx(0.3)
    assert both[1] == both[2] == 0.0  # the priority road yields to nobody
    # two road users, each on the straight route with 0.5: yields unless neither is there
    opposite = route(network, "o3", "ir3", "il1", "o1")
    two = chance_of(
        network,
        [0, 1, 1, 2, 2],
        [vertical, straight, right, opposite, route(network, "o3", "ir3", "il2", "o2")],
        [1, 0.5, 0.5, 0.5, 0.5],
        [88, 88, 88, 88, 88],
    )
    alone = chance_of(network, [0, 1], [vertical, opposite], [1, 1], [88, 88])[0]
    assert alone == 1.0 and two[0] == pytest.approx(1 - 0.5 * 0.5)


def along(belief, n, heading):
    """The box's rear and front [m] along ``heading`` at step n."""
    centre = float(belief.x[n]) * np.cos(heading) + float(belief.y[n]) * np.sin(heading)
    return centre - float(belief.half_x[n]), centre + float(belief.half_x[n])


def test_a_road_user_that_may_yield_is_held_or_free(network):
    vertical = measurement(network, ("o0", "ir0", 0), 88.0, 8.0)
    horizontal = measurement(network, ("o1", "ir1", 0), 88.0, 8.0)
    scene = np.array([vertical, horizontal])
    held_free = IntervalModel(split_yield=True)
    split = LanePredictor(network, T, longitudinal="interval", intervals=held_free).predict_scene(
        scene, STEPS
    )
    whole = LanePredictor(
        network, T, longitudinal="interval", intervals=IntervalModel(split_yield=False)
    ).predict_scene(scene, STEPS)
    labels = [m.label for m in split[0]]
    assert any(label.endswith(":held") for label in labels) and any(
        label.endswith(":free") for label in labels
    )
    assert not any(":" in m.label for m in split[1])  # the priority road's modes are whole
    for mode in whole[0]:  # held and free share their route mode's weight
        parts = [m.weight for m in split[0] if m.label.split(":")[0] == mode.label]
        assert sum(parts) == pytest.approx(mode.weight)
    heading = float(vertical[2])
    for label in {m.label.split(":")[0] for m in split[0] if m.label.endswith(":held")}:
        held = next(m for m in split[0] if m.label == label + ":held").beliefs
        free = next(m for m in split[0] if m.label == label + ":free").beliefs
        whole_box = next(m for m in whole[0] if m.label == label).beliefs
        # the held box stops short of the free one, which drives on; each is shorter than the one box
        assert along(held, STEPS, heading)[1] < along(free, STEPS, heading)[1] - 5.0
        assert held.v_hi[STEPS] < free.v_lo[STEPS]
        for part in (held, free):
            assert part.half_x[STEPS] < whole_box.half_x[STEPS]


def test_an_interval_box_is_centred_on_its_interval(network):
    horizontal = measurement(network, ("o1", "ir1", 0), 40.0, 6.0)
    boxes = {}
    for centred in (True, False):
        model = IntervalModel(split_yield=False, centred=centred)
        mixture = LanePredictor(network, T, longitudinal="interval", intervals=model).predict(
            horizontal, STEPS
        )
        boxes[centred] = mixture.modes[0].beliefs
    heading = float(horizontal[2])
    centred, about_mean = boxes[True], boxes[False]
    # same ends ahead and behind where the mean's box is longer, never the other way round
    assert np.all(centred.half_x <= about_mean.half_x + 1e-9)
    assert centred.half_x[STEPS] < about_mean.half_x[STEPS] - 0.5
    rear, front = along(centred, STEPS, heading)
    rear_m, front_m = along(about_mean, STEPS, heading)
    assert rear >= rear_m - 1e-6 and front <= front_m + 1e-6
    assert min(rear - rear_m, front_m - front) < 1e-6  # one end is the interval's own


def test_given_that_the_ego_goes_a_follower_drives_on_behind_it():
    road = RoadNetwork.straight_road_network(lanes=1, length=1000.0, speed_limit=10.0)
    ego = np.array([100.0, 0.0, 0.0, 0.0, 0.0])  # stopped, as at a stop line
    follower = np.array([75.0, 0.0, 0.0, 8.0, 0.0])
    intervals = IntervalModel(centred=True)  # each box is its interval: the runs' own bounds
    predictor = LanePredictor(road, T, longitudinal="interval", intervals=intervals, ego=lambda: ego)
    lanes = (("0", "1", 0),)
    waiting = predictor.predict_scene(follower[None], STEPS)[0].modes[0].beliefs
    going = (
        predictor.predict_scene(follower[None], STEPS, ego_plan=EgoPlan(lanes, 3.0, 8.0))[0].modes[0].beliefs
    )
    rear_waiting, _ = along(waiting, STEPS, 0.0)
    rear_going, front_going = along(going, STEPS, 0.0)
    ego_at = 100.0 + 0.5 * 3.0 * (STEPS * T) ** 2  # accelerating at 3 m/s^2 for 3 s, below 8 m/s
    # waiting, the slow run brakes behind the stopped ego; given that it goes, the follower drives on
    assert rear_going > rear_waiting + 3.0
    assert front_going < ego_at - 5.0  # and keeps its distance, never through it
    with pytest.raises(ValueError, match="EgoPlan.accel"):
        EgoPlan(lanes, 0.0, 8.0)
    with pytest.raises(ValueError, match="EgoPlan.lanes"):
        EgoPlan((), 3.0, 8.0)


def test_with_yield_to_ego_no_box_runs_through_a_standing_ego():
    """A road user stopped behind a standing ego: its box runs through the ego's rear within the
    horizon (the mean run has the ego drive off as highway-env's IDM; given that it goes, every
    run), so a plan to stand has no solution; with ``yield_to_ego`` every box ends where a run
    with the ego standing stops it, behind the ego."""
    road = RoadNetwork.straight_road_network(lanes=1, length=1000.0, speed_limit=10.0)
    ego = np.array([104.0, 0.0, 0.0, 0.0, 0.0])
    follower = np.array([96.0, 0.0, 0.0, 0.0, 0.0])  # stopped behind it, as in a queue
    ego_rear = 104.0 - 2.5
    plan = EgoPlan((("0", "1", 0),), 3.0, 8.0)

    def front(switch: bool, given: EgoPlan | None) -> float:
        intervals = IntervalModel(centred=True, split_yield=True, yield_to_ego=switch)
        predictor = LanePredictor(road, T, longitudinal="interval", intervals=intervals, ego=lambda: ego)
        beliefs = predictor.predict_scene(follower[None], STEPS, ego_plan=given)[0].modes[0].beliefs
        return max(along(beliefs, n, 0.0)[1] for n in range(STEPS + 1))

    assert front(False, None) > ego_rear + 2.5
    assert front(False, plan) > ego_rear
    assert front(True, None) < ego_rear
    assert front(True, plan) < ego_rear
    with pytest.raises(TypeError, match="yield_to_ego"):
        IntervalModel(yield_to_ego=1)


def test_the_gate_predicts_the_others_given_that_the_ego_goes(network):
    seen = []

    class Spy(LanePredictor):
        def predict_scene(self, measurements, steps, lanes=None, signals=None, ego_plan=None):
            seen.append(ego_plan)
            return super().predict_scene(measurements, steps, lanes, signals, ego_plan)

    ego = measurement(network, ("o0", "ir0", 0), 90.0, 0.0)
    predictor = Spy(network, T, longitudinal="interval", ego=lambda: ego)
    lanes = (("o0", "ir0", 0), ("ir0", "il1", 0), ("il1", "o1", 0))
    path = RoutePath.from_lanes(network, lanes)
    for given in (True, False):
        gate = JunctionGate(predictor, 4.0, 3.0, 2.5, T, given_ego=given)
        gate.route, gate.span, gate.speed_cap = path, junction_span(path), 8.0
        gate.decide(90.0, 0.0, np.array([measurement(network, ("o1", "ir1", 0), 60.0, 8.0)]))
    assert seen[0] == EgoPlan(lanes, 3.0, 8.0) and seen[1] is None
    assert dataclasses.replace(seen[0], speed=9.0) != seen[0]


def test_with_ego_ahead_the_fast_run_brakes_for_an_ego_in_the_junction(network):
    """An ego standing 8 m into the junction, on the straight lane a road user's approach leads to:
    highway-env's traffic brakes for it (its connected search finds it on the next lane), and so
    does every run with ``ego_ahead``; without it the fast run, which searches the own lane only,
    drives through the ego."""
    ego = measurement(network, ("ir1", "il3", 0), 8.0, 0.0)
    follower = measurement(network, ("o1", "ir1", 0), 82.0, 8.0)
    heading = float(follower[2])
    direction = np.array([np.cos(heading), np.sin(heading)])
    ego_rear = float(ego[:2] @ direction) - 2.5

    def front(switch: bool) -> float:
        intervals = IntervalModel(centred=True, ego_ahead=switch)
        predictor = LanePredictor(network, T, longitudinal="interval", intervals=intervals, ego=lambda: ego)
        mixture = predictor.predict_scene(follower[None], STEPS)[0]
        return max(along(mode.beliefs, n, heading)[1] for mode in mixture.modes for n in range(STEPS + 1))

    assert front(False) > ego_rear + 2.0
    assert front(True) < ego_rear
    with pytest.raises(TypeError, match="ego_ahead"):
        IntervalModel(ego_ahead=1)
