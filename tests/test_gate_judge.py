"""The junction gate's judge (risk_env.highway.gate_judge): a mode's mean car instead of its boxes,
a chance of conflict summed over each vehicle's modes, the settings the adapter passes, and the
turn signals the adapter reads from highway-env's observation and hands on."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from risk_env.highway.gate import GateError, GatePredictor, JunctionGate, check_gate
from risk_env.highway.gate_judge import (
    CAR_HALF_LENGTH,
    NEAR_STEPS,
    GateSettings,
    conflict_chance,
    judged,
)
from risk_env.highway.lanes.predictor import EgoPlan
from risk_env.prediction.mixture import Mixture, Mode
from risk_env.prediction.predictors import Predictor
from risk_env.scenario.scenario import Scenario
from tests.test_gate import DT, ROUTE, Crossing, crossing_at


class TwoWays(Predictor):
    """Each road user either crosses the route (weight ``w``) or turns away from it along -y."""

    name = "two ways"
    max_modes = 2

    def __init__(self, w: float) -> None:
        self.w = w

    def predict(self, measurement, steps):
        crossing = Crossing().predict(measurement, steps).modes[0].beliefs
        away = dataclasses.replace(crossing, y=2 * float(measurement[1]) - crossing.y, theta=-crossing.theta)
        return Mixture((Mode(self.w, crossing, "crosses"), Mode(1 - self.w, away, "turns away")))


def gate(predictor, **options) -> JunctionGate:
    g = JunctionGate(predictor, reach=4.0, accel=3.0, half_length=2.5, dt=DT, **options)
    g.reset(ROUTE, Scenario.preset("low", v_ref=8.0, v_max=10.0, v_min=0.0))
    return g


def test_a_mode_judged_by_its_mean_car_is_the_car_about_its_mean():
    belief = Crossing(growth=30.0).predict(crossing_at(60.0, -20.0, 10.0)[0], 4).modes[0].beliefs
    mode = Mode(0.3, belief, "m")
    boxes, car = judged(mode, "boxes").modes[0], judged(mode, "footprint").modes[0]
    assert boxes.weight == car.weight == 1.0
    assert np.array_equal(boxes.beliefs.half_x, belief.half_x)
    assert np.all(car.beliefs.half_x == CAR_HALF_LENGTH) and np.allclose(car.beliefs.frame, math.pi / 2)
    assert np.array_equal(car.beliefs.x, belief.x) and np.array_equal(car.beliefs.y, belief.y)


def test_boxes_that_grow_close_the_gate_where_the_mean_car_leaves_it_open():
    # its bound growing 30 m/s ahead of it reaches the zone in time, its mean car does not
    far = crossing_at(60.0, -80.0, 10.0)
    assert gate(Crossing(growth=30.0)).decide(30.0, 5.0, far).closed
    assert not gate(Crossing(growth=30.0), judge="footprint").decide(30.0, 5.0, far).closed
    near = crossing_at(60.0, -30.0, 10.0)  # its mean car is in the zone while the ego is
    assert gate(Crossing(), judge="footprint").decide(30.0, 5.0, near).closed


def test_a_gate_kept_open_closes_again_only_for_its_keep_open_judges_conflict():
    far, near = crossing_at(60.0, -80.0, 10.0), crossing_at(60.0, -30.0, 10.0)
    empty = np.zeros((0, 5))
    kept = gate(Crossing(growth=30.0), keep_open="footprint")
    assert kept.decide(30.0, 5.0, far).closed  # never opened: judged by its boxes
    assert not kept.decide(30.0, 5.0, empty).closed  # open with nobody about: not a gap taken
    assert kept.decide(30.0, 5.0, far).closed
    kept = gate(Crossing(growth=30.0), keep_open="footprint")
    assert not kept.decide(30.0, 5.0, crossing_at(60.0, -400.0, 10.0)).closed  # a gap, taken
    assert not kept.decide(30.0, 5.0, far).closed  # its boxes conflict, its mean car does not
    assert kept.decide(30.0, 5.0, near).closed  # its mean car does
    assert kept.decide(30.0, 5.0, far).closed  # closed again: judged by its boxes
    plain = gate(Crossing(growth=30.0))
    assert not plain.decide(30.0, 5.0, crossing_at(60.0, -400.0, 10.0)).closed
    assert plain.decide(30.0, 5.0, far).closed  # without keep_open the boxes close it


def test_the_near_judge_takes_the_boxes_over_the_horizon_and_the_mean_car_after():
    belief = Crossing(growth=30.0).predict(crossing_at(60.0, -20.0, 10.0)[0], 10).modes[0].beliefs
    near = judged(Mode(0.3, belief, "m"), "near").modes[0].beliefs
    boxes = slice(0, NEAR_STEPS + 1)
    assert np.array_equal(near.half_x[boxes], belief.half_x[boxes])
    assert np.array_equal(near.frame[boxes], belief.frame[boxes])
    assert np.all(near.half_x[NEAR_STEPS + 1 :] == CAR_HALF_LENGTH)
    assert np.allclose(near.frame[NEAR_STEPS + 1 :], belief.theta[NEAR_STEPS + 1 :])
    assert np.array_equal(near.x, belief.x) and np.array_equal(near.y, belief.y)
    # a bound that reaches the zone only after the horizon, at 10 s from 4.5 s on: the boxes close
    # the gate, the near judge does not; one that reaches it within the horizon closes both
    late = crossing_at(60.0, -200.0, 10.0)
    assert gate(Crossing(growth=40.0)).decide(30.0, 5.0, late).closed
    assert not gate(Crossing(growth=40.0), judge="near").decide(30.0, 5.0, late).closed
    soon = crossing_at(60.0, -80.0, 10.0)
    assert gate(Crossing(growth=30.0), judge="near").decide(30.0, 5.0, soon).closed


def test_the_chance_of_a_conflict_sums_each_vehicles_conflicting_modes():
    assert conflict_chance([]) == 0.0
    assert conflict_chance([0.2, 0.5]) == pytest.approx(1 - 0.8 * 0.5)
    near = crossing_at(60.0, -30.0, 10.0)
    # one vehicle crossing with weight 0.3: closed at any conflict, open when 0.3 is tolerated
    assert gate(TwoWays(0.3)).decide(30.0, 5.0, near).closed
    assert gate(TwoWays(0.3), tolerance=0.25).decide(30.0, 5.0, near).closed
    assert not gate(TwoWays(0.3), tolerance=0.35).decide(30.0, 5.0, near).closed
    # two such vehicles: 1 - 0.7^2 = 0.51
    two = np.vstack([near, crossing_at(62.0, -30.0, 10.0)])
    assert gate(TwoWays(0.3), tolerance=0.5).decide(30.0, 5.0, two).closed
    assert not gate(TwoWays(0.3), tolerance=0.52).decide(30.0, 5.0, two).closed


def test_the_settings_reach_the_gate_and_bad_ones_are_named():
    assert check_gate(True) == GateSettings() and check_gate(False) is None
    mine = GateSettings(clearance=2.0, judge="near", tolerance=0.1, given_ego=True, slow_approach=True)
    assert check_gate(mine) is mine
    with pytest.raises(GateError, match="gate must be True, False"):
        check_gate("footprint")
    with pytest.raises(ValueError, match="judge"):
        gate(Crossing(), judge="means")
    with pytest.raises(GateError, match="tolerance must lie in"):
        gate(Crossing(), tolerance=1.0)
    with pytest.raises(ValueError, match="keep_open"):
        gate(Crossing(), keep_open="rollout")


class Recorder(Predictor):
    """Records the signals a lane-predictor-like inner predictor is given."""

    name = "recorder"
    max_modes = 1

    def __init__(self) -> None:
        self.seen = []

    def predict(self, measurement, steps):
        return Crossing().predict(measurement, steps)


def test_the_agents_predictor_gets_each_rows_observed_turn_signal(monkeypatch):
    from risk_env.highway import predictors as gate_module

    inner = Recorder()

    def predict_scene(rows, steps, signals=None, ego_plan=None):
        inner.seen.append(signals)
        inner.plans.append(ego_plan)
        return [inner.predict(row, steps) for row in rows]

    inner.plans = []

    inner.predict_scene = predict_scene
    monkeypatch.setattr(gate_module, "LanePredictor", Recorder)  # it reads signals as a lane predictor
    wrapper = GatePredictor(inner)
    others = np.array([[10.0, 0.0, 0.0, 5.0, 0.0], [20.0, 3.0, 0.0, 5.0, 0.0]])
    wrapper.signals = (others, [np.array([0.0, 1.0]), None])
    asked = np.vstack([others[1], others[0] + 0.01, [90.0, 90.0, 0.0, 1.0, 0.0]])  # float32 rounding
    wrapper.predict_scene(asked, 3)
    got = inner.seen[-1]
    assert got[0] is None and np.array_equal(got[1], [0.0, 1.0]) and got[2] is None
    wrapper.signals = None
    wrapper.predict_scene(asked, 3)
    assert inner.seen[-1] is None and inner.plans == [None, None]
    plan = EgoPlan((("o0", "ir0", 0),), 3.0, 8.0)  # the gate's, while it is open with given_ego
    wrapper.ego_plan = plan
    wrapper.predict_scene(asked, 3)
    assert inner.plans[-1] is plan


def test_an_open_gate_given_the_ego_tells_the_agents_predictor_that_the_ego_goes():
    wrapper = GatePredictor(Crossing())
    for given, others, going in (
        (True, crossing_at(60.0, -300.0, 10.0), True),  # open: the ego goes
        (True, crossing_at(60.0, -30.0, 10.0), False),  # closed: it waits
        (False, crossing_at(60.0, -300.0, 10.0), False),  # not asked to
    ):
        g = gate(Crossing(), given_ego=given)
        g.wrapper = wrapper
        g.step(30.0, 5.0, others)
        assert (wrapper.ego_plan is not None) is going
        if going:
            assert wrapper.ego_plan == EgoPlan(ROUTE.lanes, 3.0, 8.0)


def test_the_adapter_reads_turn_signals_only_from_an_env_that_observes_them():
    pytest.importorskip("highway_env")
    from risk_env.highway import make_intersection_env
    from risk_env.highway.common import SIGNAL_FEATURES, turn_signals

    plain = make_intersection_env()
    obs, _ = plain.reset(seed=0)
    assert turn_signals(plain.unwrapped, obs) is None
    env = make_intersection_env(signals=True)
    obs, _ = env.reset(seed=0)
    assert list(env.unwrapped.observation_type.features[-2:]) == list(SIGNAL_FEATURES)
    signals = turn_signals(env.unwrapped, obs)
    others = [
        v for v in env.unwrapped.road.close_vehicles_to(env.unwrapped.vehicle, 1e9, count=14, see_behind=True)
    ]
    assert len(signals) == int((obs[:, 0] > 0.5).sum()) - 1
    for shown, vehicle in zip(signals, others, strict=False):  # sorted by distance, as the observation
        assert np.allclose(shown, vehicle.destination_direction, atol=1e-6)


def test_the_commands_defaults_are_the_adapters():
    pytest.importorskip("highway_env")
    from benchmarks import highway_intersection
    from benchmarks.highway_agents import ADAPTER_CORRIDOR, ADAPTER_OBJECT_RADIUS, gate_settings
    from risk_env.highway.adapter import ADAPTER_DEFAULTS

    assert ADAPTER_DEFAULTS["corridor"] == ADAPTER_CORRIDOR
    assert ADAPTER_DEFAULTS["object_radius"] == ADAPTER_OBJECT_RADIUS
    args = highway_intersection.parse_args([])
    assert gate_settings(args) == GateSettings() and args.object_radius == ADAPTER_OBJECT_RADIUS
    args = highway_intersection.parse_args(
        [
            "--gate-judge",
            "footprint",
            "--gate-tolerance",
            "0.1",
            "--gate-given-ego",
            "--gate-keep-open",
            "near",
        ]
    )
    assert gate_settings(args) == GateSettings(
        judge="footprint", tolerance=0.1, given_ego=True, keep_open="near"
    )
    assert gate_settings(highway_intersection.parse_args(["--no-gate"])) is False
    args = highway_intersection.parse_args(["--predictor", "lane+interval", "--gate-passage"])
    assert gate_settings(args) == GateSettings(passage=True)
    from benchmarks.highway_agents import make_driver, resolve
    from risk_env.highway import make_intersection_env

    args = highway_intersection.parse_args(["--object-radius", "1"])
    driver = make_driver(resolve("rmpc", args.severity, args.budget), make_intersection_env(), args, "lane")
    assert driver.base_scenario.objects[0].radius == 1.0 and driver.base_scenario.ego.radius == 2.0


def west_road(back: float, speed: float):
    """intersection-v2's map, the ego's left turn through the junction sampled every metre ``(J, 2)``,
    and the modes (by route) of a vehicle on the west road ``back`` metres before the junction at
    ``speed`` [m/s], on the interval prediction with fitted boxes."""
    pytest.importorskip("highway_env")
    from risk_env.highway import LanePredictor, make_intersection_env
    from risk_env.highway.lanes.interval import IntervalModel
    from risk_env.highway.lanes.routes import Route

    env = make_intersection_env()
    env.reset(seed=0)
    network = env.unwrapped.road.network
    model = IntervalModel(split_yield=True, centred=True, fitted=True)
    predictor = LanePredictor(network, DT, longitudinal="interval", intervals=model)
    left_turn = Route(network, (("ir0", "il1", 0),))
    points = left_turn.position(np.arange(0.0, left_turn.length, 1.0))
    lane = network.get_lane(("o1", "ir1", 0))
    x, y = lane.position(lane.length - back, 0.0)
    measured = np.array([x, y, lane.heading_at(lane.length - back), speed, 0.0])
    return points, {m.label: m for m in predictor.predict(measured, 12).modes}


RIGHT, STRAIGHT, LEFT = "o1>ir1>il0>o0", "o1>ir1>il3>o3", "o1>ir1>il2>o2"


def test_the_stretch_judge_sees_a_crossing_and_not_a_turn_beside_the_egos():
    from risk_env.highway.gate_judge import occupancy

    points, modes = west_road(5.0, 6.0)
    first = {}
    for label, mode in modes.items():
        assert mode.stretch is not None and mode.stretch.points.shape[0] == 13
        for judge, steps in (("near", 0), ("stretch", NEAR_STEPS)):
            first[label, judge] = float(
                np.min(occupancy(judged(mode, judge), points, 2.0, DT, 0.0, steps)[0])
            )
    # its right turn runs 4 m inside the ego's left turn: the box about the arc reaches over it, the
    # stretch never comes within 2 m
    assert first[RIGHT, "near"] < NEAR_STEPS * DT
    assert first[RIGHT, "stretch"] == math.inf
    # straight on, or turning left, it crosses the ego's path: the stretch sees it as soon as the box does
    for label in (STRAIGHT, LEFT):
        assert first[label, "stretch"] <= first[label, "near"] < NEAR_STEPS * DT


def test_the_tracks_judge_counts_the_share_of_a_vehicles_speeds_that_meet_the_ego():
    from risk_env.highway.gate_judge import mode_conflict

    points, modes = west_road(15.0, 6.0)

    def judge(label: str, t0: float, name: str = "tracks") -> tuple[float, float]:
        ego_in = np.full(len(points), t0)  # the ego at every point from t0 for 0.6 s
        return mode_conflict(modes[label], name, points, 2.0, DT, ego_in, ego_in + 0.6, 0.25)

    # straight on it crosses the ego's path between 2 and 4 s, the fast tracks first
    shares = [judge(STRAIGHT, t0)[1] for t0 in (0.0, 2.0, 3.0, 5.0)]
    assert shares[0] == 0.0 and 0.0 < shares[1] < shares[2] and shares[3] < shares[2]
    apart, share = judge(STRAIGHT, 0.0)
    assert apart >= 0.25 and share == 0.0  # the ego has gone before the fastest track comes
    apart, share = judge(STRAIGHT, 2.0)
    assert apart < 0.25 and 0.0 < share < 1.0
    # the box judges the mode whole: it conflicts wherever a track does
    assert judge(STRAIGHT, 2.0, "near")[1] == 1.0
    # its right turn, 4 m inside the ego's left turn, never meets it
    assert all(judge(RIGHT, t0) == (math.inf, 0.0) for t0 in (0.0, 2.0, 3.0, 5.0))
