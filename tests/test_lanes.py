"""The lane predictor against highway-env's own lanes, IDM and yielding rule, and the prediction
benchmark on a short episode."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

pytest.importorskip("highway_env")

from highway_env.road.lane import StraightLane  # noqa: E402
from highway_env.road.road import Road, RoadNetwork  # noqa: E402
from highway_env.utils import rotated_rectangles_intersect  # noqa: E402
from highway_env.vehicle.behavior import IDMVehicle  # noqa: E402

from benchmarks import prediction as bench  # noqa: E402
from benchmarks import prediction_samples as samples  # noqa: E402
from risk_env.highway import LaneMode, LanePredictor, vehicle_measurement  # noqa: E402
from risk_env.highway.lanes.beliefs import Spread  # noqa: E402
from risk_env.highway.lanes.routes import (  # noqa: E402
    Route,
    lane_coordinates,
    lane_headings,
    lane_points,
    rectangles_intersect,  # noqa: E402
    routes_from,
)
from risk_env.highway.lanes.speed import TrafficModel, reach  # noqa: E402
from risk_env.highway.lanes.table import LaneTable  # noqa: E402
from risk_env.highway.lanes.weights import WeightModel  # noqa: E402
from risk_env.models.frame import to_frame  # noqa: E402
from risk_env.prediction import ConstantPredictor, Mixture, make_predictor  # noqa: E402
from risk_env.scenario.scenario import Scenario  # noqa: E402

T = 0.5
STEPS = 6


@pytest.fixture(scope="module")
def predictor(network):
    return LanePredictor(network, T)


def alone(network, lane_index, s, speed, destination=None, frames=0):
    """A highway-env IDM vehicle on ``lane_index`` at ``s`` [m], alone on the road, after ``frames``
    simulation frames (16 Hz) of driving toward ``destination``: its measurement."""
    road = Road(network=network)
    lane = network.get_lane(lane_index)
    vehicle = IDMVehicle(road, lane.position(s, 0.0), heading=lane.heading_at(s), speed=speed)
    if destination:
        vehicle.plan_route_to(destination)
    road.vehicles = [vehicle]
    for _ in range(frames):
        road.act()
        road.step(1 / 16)
    vehicle.act()
    return vehicle_measurement(vehicle)


def weight_of(mixture: Mixture, node: str) -> float:
    """The weight of the routes through ``node``."""
    return sum(w for mode in mixture for label, w in mode.routes if node in label.split(">"))


# ------------------------------------------------------------------------------------ geometry
def test_vectorised_lane_calls_are_the_lanes_own(network):
    rng = np.random.default_rng(0)
    for lane in network.lanes_list():
        points = rng.uniform(-60, 60, (20, 2))
        s, r = lane_coordinates(lane, points)
        assert np.allclose(np.column_stack([s, r]), [lane.local_coordinates(p) for p in points])
        along = rng.uniform(-10, lane.length + 10, 12)
        side = rng.uniform(-2, 2, 12)
        assert np.allclose(lane_points(lane, along, side), [lane.position(a, b) for a, b in zip(along, side)])
        assert np.allclose(lane_headings(lane, along), [lane.heading_at(a) for a in along])
    table = LaneTable(network, connected=True)
    points, headings = rng.uniform(-40, 40, (300, 2)), rng.uniform(-4, 4, 300)
    s, r = table.locate(points)
    closest = [table.indices[i] for i in table.closest(s, r, headings)]
    assert closest == [tuple(network.get_closest_lane_index(p, h)) for p, h in zip(points, headings)]


def test_a_route_follows_its_lanes_and_ends_where_the_graph_turns_back(network):
    (route,) = [Route(network, lanes) for lanes in routes_from(network, ("il1", "o1", 0), 10.0, 30.0, 150.0)]
    assert route.lanes == (("il1", "o1", 0),)  # o1 -> ir1 starts 4 m away, facing back: no continuation
    routes = [Route(network, lanes) for lanes in routes_from(network, ("o0", "ir0", 0), 90.0, 30.0, 150.0)]
    assert sorted(r.lanes[1][1] for r in routes) == ["il1", "il2", "il3"]
    for route in routes:
        for k, lane in enumerate(route.objects):
            s = np.linspace(0, lane.length, 7)
            assert np.allclose(
                route.position(route.offsets[k] + s), [lane.position(x, 0) for x in s], atol=5e-3
            )


def test_rectangles_intersect_as_highway_env_decides():
    rng = np.random.default_rng(1)
    c1, c2 = rng.uniform(-5, 5, (500, 2)), rng.uniform(-5, 5, (500, 2))
    a1, a2 = rng.uniform(-4, 4, 500), rng.uniform(-4, 4, 500)
    ours = rectangles_intersect(c1, a1, c2, a2, 7.5, 1.8)
    theirs = [
        rotated_rectangles_intersect((p, 7.5, 1.8, a), (q, 7.5, 1.8, b)) for p, a, q, b in zip(c1, a1, c2, a2)
    ]
    assert ours.tolist() == theirs and 0.2 < ours.mean() < 0.8


def test_reach_brakes_to_a_stop_and_accelerates_to_the_limit():
    low, high = reach(8.0, 10.0, 6, T, 6.0)
    assert low[-1] == pytest.approx(8.0**2 / 12) and low[1] == pytest.approx(8 * 0.5 - 3 * 0.25)
    t_top = 2 / 6
    assert high[-1] == pytest.approx(8 * t_top + 3 * t_top**2 + 10 * (3 - t_top))


# ------------------------------------------------------------------------------------ modes
@pytest.mark.parametrize("turn", ["il1", "il2", "il3"])
def test_a_vehicle_mid_turn_has_one_mode_its_turn(network, predictor, turn):
    lane = network.get_lane(("ir0", turn, 0))
    m = alone(network, ("ir0", turn, 0), lane.length / 2, 7.0, destination=f"o{turn[-1]}")
    mixture = predictor.predict(m, STEPS)
    assert len(mixture) == 1 and isinstance(mixture.modes[0], LaneMode)
    assert mixture.modes[0].label.startswith(f"ir0>{turn}") and mixture.modes[0].weight == 1.0


@pytest.mark.parametrize("destination", ["o1", "o2", "o3"])
def test_a_vehicle_that_has_begun_its_turn_is_predicted_turning(network, predictor, destination):
    # highway-env's IDM drives from 12 m before the junction until 3 m into its turn lane
    m = alone(network, ("o0", "ir0", 0), 88.0, 8.0, destination=destination, frames=30)
    node = "il" + destination[-1]
    assert weight_of(predictor.predict(m, STEPS), node) > 0.95


@pytest.mark.parametrize(("s", "speed"), [(1.0, -10.0), (0.5, -14.0), (99.0, 10.0), (50.0, 0.0)])
def test_a_vehicle_rolling_backwards_or_at_a_lane_end_gets_its_lane(network, predictor, s, speed):
    lane = network.get_lane(("il1", "o1", 0))
    x, y = lane.position(s, 0.0)
    mixture = predictor.predict([x, y, lane.heading_at(s), speed, 0.0], STEPS)
    assert [m.label for m in mixture] == ["il1>o1"] and mixture.modes[0].weight == 1.0
    assert mixture.modes[0].beliefs.speed[-1] <= max(speed, 0.0) + 6 * 3


def test_far_from_a_junction_one_mode_near_it_one_per_turn(network, predictor):
    far = predictor.predict(alone(network, ("o0", "ir0", 0), 20.0, 8.0), STEPS)
    assert [m.label for m in far] == ["o0>ir0"] and far.modes[0].weight == 1.0
    assert len(far.modes[0].routes) == 3  # the routes it stands for, weighted by the prior
    near = predictor.predict(alone(network, ("o0", "ir0", 0), 90.0, 8.0), STEPS)
    assert len(near) == 3 and np.allclose(near.weights, 1 / 3)
    assert near.most_likely().label == "o0>ir0>il2"  # straight on, between the two turns
    straight = RoadNetwork.straight_road_network(lanes=1, length=500.0)
    mixture = LanePredictor(straight, T).predict([100.0, 0.0, 0.0, 10.0, 0.0], STEPS)
    assert len(mixture) == 1 and mixture.modes[0].weight == 1.0


def test_the_means_lie_on_the_centrelines_and_the_spread_in_the_lane(network, predictor):
    mixture = predictor.predict(alone(network, ("o0", "ir0", 0), 85.0, 8.0), STEPS)
    assert len(mixture) == 3
    for mode in mixture:
        (label, _), *_ = mode.routes
        nodes = label.split(">")
        lanes = [network.get_lane((a, b, 0)) for a, b in zip(nodes, nodes[1:])]
        b = mode.beliefs
        for n in range(STEPS + 1):
            offsets = [abs(lane.local_coordinates(np.array([b.x[n], b.y[n]]))[1]) for lane in lanes]
            assert min(offsets) < 1e-2
            assert 0 < b.sigma_y[n] <= 2.0 and b.sigma_x[n] <= b.half_x[n]  # lanes are 4 m wide
            assert b.v_lo[n] <= b.speed[n] <= b.v_hi[n]
        assert np.all(np.diff(b.half_x) > 0) and b.half_x[-1] > 10  # braking to accelerating


def test_draws_of_a_lane_belief_fall_in_its_box_as_the_benchmark_tests_it(network, predictor):
    mixture = predictor.predict(alone(network, ("ir0", "il1", 0), 3.0, 6.0, destination="o1"), STEPS)
    rng = np.random.default_rng(2)
    for mode in mixture:
        belief = mode.beliefs[STEPS]
        assert belief.frame != 0.0
        draws = belief.sample(rng, 400)
        assert all(samples._inside(mode, STEPS, point)[0] for point in draws[:, :2])
        assert np.all((draws[:, 2] >= belief.v_lo) & (draws[:, 2] <= belief.v_hi))


def test_a_box_on_a_curve_holds_the_arc_the_vehicle_can_reach(network, predictor):
    m = alone(network, ("ir0", "il1", 0), 2.0, 5.0, destination="o1")  # a right turn, radius 9 m
    (mode,) = [mode for mode in predictor.predict(m, STEPS) if mode.label.startswith("ir0>il1")]
    route = Route(network, (("ir0", "il1", 0), ("il1", "o1", 0)))
    start = route.locate(m[:2])[0]
    low, high = reach(5.0, 10.0, STEPS, T, 6.0)
    for n in range(1, STEPS + 1):
        arc = route.position(np.linspace(start + low[n], start + high[n], 50))
        assert all(samples._inside(mode, n, point)[0] for point in arc)
    b = mode.beliefs  # round a quarter circle: well under the square on the stretch's length
    assert 4 * b.half_x[-1] * b.half_y[-1] < 0.6 * (high[-1] - low[-1] + 1) ** 2


def test_the_box_along_the_lane_reaches_from_full_braking_to_full_acceleration():
    straight = RoadNetwork.straight_road_network(lanes=1, length=1000.0, speed_limit=10.0)
    spread = Spread(margin_along=0.0)
    mode = LanePredictor(straight, T, spread=spread).predict([100.0, 0.0, 0.0, 8.0, 0.0], STEPS).modes[0]
    b = mode.beliefs
    low, high = reach(8.0, 10.0, STEPS, T, 6.0)
    assert np.all(b.x - b.half_x <= 100 + low + 1e-9) and np.all(b.x + b.half_x >= 100 + high - 1e-9)
    assert np.allclose(b.frame, 0.0) and np.allclose(b.half_y, spread.margin_across)


def test_the_speed_model_is_highway_envs_idm_behind_a_leader():
    straight = RoadNetwork.straight_road_network(lanes=1, length=1000.0, speed_limit=15.0)
    road = Road(network=straight)
    follower, leader = IDMVehicle(road, [100.0, 0.0], 0.0, 9.0), IDMVehicle(road, [125.0, 0.0], 0.0, 4.0)
    road.vehicles = [follower, leader]
    measurements = np.array([vehicle_measurement(v) for v in road.vehicles])
    traffic = TrafficModel(
        comfort_acceleration=IDMVehicle.COMFORT_ACC_MAX,
        comfort_deceleration=-IDMVehicle.COMFORT_ACC_MIN,
        distance_wanted=IDMVehicle.DISTANCE_WANTED,
        time_wanted=IDMVehicle.TIME_WANTED,
        delta=IDMVehicle.DELTA,
        cruise_speed=0.0,  # each keeps its own speed as its target, as highway-env's vehicles here
        substeps=8,  # highway-env's 16 Hz
    )
    mixtures = LanePredictor(straight, T, traffic=traffic).predict_scene(measurements, STEPS)
    for n in range(1, STEPS + 1):
        for _ in range(8):
            road.act()
            road.step(1 / 16)
        b = mixtures[0].modes[0].beliefs
        assert b.x[n] == pytest.approx(follower.position[0], abs=1e-6)
        assert b.speed[n] == pytest.approx(follower.speed, abs=1e-6)
    assert follower.speed < 6.0  # it did brake


def test_the_lower_priority_vehicle_yields(network, predictor):
    vertical = alone(network, ("o0", "ir0", 0), 88.0, 8.0)  # priority 1
    horizontal = alone(network, ("o1", "ir1", 0), 88.0, 8.0)  # priority 3
    together = predictor.predict_scene(np.array([vertical, horizontal]), STEPS)
    by_itself = predictor.predict(vertical, STEPS)
    assert together[0].most_likely().beliefs.speed[2] < 3.0 < by_itself.most_likely().beliefs.speed[2]
    assert together[1].most_likely().beliefs.speed[2] > 7.0


def test_the_turn_signal_tells_the_route(network, predictor):
    m = alone(network, ("o0", "ir0", 0), 90.0, 8.0)
    end = network.get_lane(("il3", "o3", 0)).position(100.0, 0.0)
    signal = (end - m[:2]) / np.hypot(*(end - m[:2]))
    assert weight_of(predictor.predict(m, STEPS, signal=signal), "il3") > 0.99


# ------------------------------------------------------------------------------------ bad input
def test_off_the_road_falls_back_to_the_constant_predictor_and_is_counted(network):
    predictor = LanePredictor(network, T)
    m = np.array([300.0, 300.0, 0.3, 5.0, 0.1])
    mixture = predictor.predict(m, STEPS)
    assert predictor.fallbacks == 1 and predictor.predicted == 1
    assert not isinstance(mixture.modes[0], LaneMode)
    expected = ConstantPredictor(Scenario.preset("low", dt=T, velocity_bounds0=(-40.0, 40.0))).predict(
        m, STEPS
    )
    assert np.array_equal(mixture.modes[0].beliefs.as_array(), expected.modes[0].beliefs.as_array())


def test_bad_inputs_name_what_is_wrong(network, predictor):
    m = alone(network, ("o0", "ir0", 0), 20.0, 8.0)
    with pytest.raises(ValueError, match=r"lane \('x', 'y', 0\) is not in the road network; its roads are"):
        predictor.predict(m, STEPS, lane=("x", "y", 0))
    with pytest.raises(ValueError, match="measurements must be finite, of shape \\(m, 5\\)"):
        predictor.predict_scene(np.zeros((2, 4)), STEPS)
    with pytest.raises(ValueError, match="lanes must have one entry per road user"):
        predictor.predict_scene(np.array([m, m]), STEPS, lanes=[None])
    with pytest.raises(TypeError, match="road_network must be highway-env's RoadNetwork"):
        LanePredictor(object(), T)
    with pytest.raises(ValueError, match="dt"):
        LanePredictor(network, -1.0)
    with pytest.raises(ValueError, match="TrafficModel.substeps must be an integer >= 1"):
        TrafficModel(substeps=0)
    with pytest.raises(ValueError, match="WeightModel.turn_prior must not be all zero"):
        WeightModel(turn_prior=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="Spread.margin_along must be a finite number >= 0"):
        Spread(margin_along=-1.0)
    with pytest.raises(ValueError, match="LanePredictor"):
        make_predictor("lane", Scenario())
    empty = RoadNetwork()
    empty.add_lane("a", "b", StraightLane([0, 0], [10, 0]))
    assert len(LanePredictor(empty, T).predict([5.0, 0.0, 0.0, 1.0, 0.0], 0)) == 1


# ------------------------------------------------------------------------------------ the benchmark
def test_brier_scores_the_route_weights_against_the_route_taken(network, predictor):
    mixture = predictor.predict(alone(network, ("o0", "ir0", 0), 90.0, 8.0), STEPS)
    assert samples.brier(mixture, ("o0", "ir0", "il1", "o1")) == pytest.approx(2 / 3)
    assert math.isnan(samples.brier(ConstantPredictor(Scenario()).predict(np.zeros(5), 3), ("o0",)))
    box = mixture.modes[0].beliefs[STEPS]
    along, across = to_frame(1.0, 0.0, float(box.frame))
    assert abs(along) <= box.half_x and samples.phase_of(("ir0", "il1", 0)) == "junction"


def test_the_benchmark_scores_a_short_episode(tmp_path):
    rows = bench.main(["--episodes", "1", "--duration", "2", "--workers", "1", "--out", str(tmp_path)])
    names = {(r["predictor"], r["phase"]) for r in rows}
    assert ("constant", "all") in names and ("lane", "all") in names
    for r in rows:
        assert 0 <= r["coverage"] <= 1 and r["samples"] > 0 and r["fallbacks"] >= 0
        assert (r["route_brier"] == "") == (r["predictor"] == "constant")
    text = (tmp_path / "prediction.md").read_text()
    assert "python -m benchmarks.prediction --episodes 1" in text and "lowest coverage" in text
    assert (tmp_path / "prediction.png").stat().st_size > 10_000


def test_pieces_split_each_route_into_bands_that_hold_its_arc_in_smaller_boxes(network, predictor):
    """``pieces=P``: P modes per route, each 1/P of its weight (share 1/P, so a threshold compares
    the route's weight), their boxes together holding the reachable arc in less area than one."""
    m = alone(network, ("ir0", "il1", 0), 2.0, 5.0, destination="o1")
    split = LanePredictor(network, T, pieces=3)
    assert split.max_modes == 9 and predictor.max_modes == 3
    whole = [mode for mode in predictor.predict(m, STEPS) if mode.label.startswith("ir0>il1")][0]
    parts = [mode for mode in split.predict(m, STEPS) if mode.label.startswith("ir0>il1")]
    assert [p.label.rsplit("#", 1)[1] for p in parts] == ["1/3", "2/3", "3/3"]
    assert all(p.share == pytest.approx(1 / 3) for p in parts)
    assert sum(p.weight for p in parts) == pytest.approx(whole.weight)
    route = Route(network, (("ir0", "il1", 0), ("il1", "o1", 0)))
    start = route.locate(m[:2])[0]
    low, high = reach(5.0, 10.0, STEPS, T, 6.0)
    for n in range(1, STEPS + 1):
        arc = route.position(np.linspace(start + low[n], start + high[n], 60))
        assert all(any(samples._inside(p, n, point)[0] for p in parts) for point in arc)
    area = sum(4 * p.beliefs.half_x[-1] * p.beliefs.half_y[-1] for p in parts)
    assert area < 0.8 * 4 * whole.beliefs.half_x[-1] * whole.beliefs.half_y[-1]
    kept = split.predict(m, STEPS).above(whole.weight * 0.99)
    assert {p.label for p in parts} <= {k.label for k in kept}  # every piece of a likely route


def test_a_mode_share_outside_zero_one_is_named(network, predictor):
    mode = predictor.predict(alone(network, ("o0", "ir0", 0), 20.0, 8.0), STEPS).modes[0]
    with pytest.raises(ValueError, match=r"modes\[0\].share"):
        Mixture((dataclasses.replace(mode, share=0.0),))
    with pytest.raises(ValueError, match="pieces"):
        LanePredictor(network, T, pieces=0)
