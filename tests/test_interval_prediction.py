"""The lane predictor's interval prediction over highway-env's IDM parameters (``"lane+interval"``):
its bounds hold highway-env's own vehicles with sampled parameters, its boxes lie within the
full-range ones, the ego takes part in the scene, and bad names and numbers are named."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("highway_env")

from highway_env.road.road import Road, RoadNetwork  # noqa: E402
from highway_env.vehicle.behavior import IDMVehicle  # noqa: E402

from benchmarks import highway_intersection  # noqa: E402
from benchmarks.highway_agents import make_driver, resolve  # noqa: E402
from risk_env.highway import LanePredictor, make_intersection_env, vehicle_measurement  # noqa: E402
from risk_env.highway.lanes.interval import IntervalModel  # noqa: E402
from risk_env.highway.predictors import highway_predictor  # noqa: E402
from risk_env.models.frame import to_frame  # noqa: E402
from risk_env.prediction import make_predictor  # noqa: E402
from risk_env.scenario.scenario import Scenario  # noqa: E402

T = 0.5
STEPS = 6


class Traffic(IDMVehicle):
    """highway-env's IDM vehicle with the numbers ``intersection-v2`` gives its traffic."""

    COMFORT_ACC_MAX = 6.0
    COMFORT_ACC_MIN = -3.0
    DISTANCE_WANTED = 7.0


@pytest.fixture(scope="module")
def env():
    env = make_intersection_env()
    env.reset(seed=0)
    return env


@pytest.fixture(scope="module")
def straight():
    return RoadNetwork.straight_road_network(lanes=1, length=1000.0, speed_limit=10.0)


def inside(mode, n, point) -> bool:
    b = mode.beliefs[n]
    along, across = to_frame(point[0] - float(b.x), point[1] - float(b.y), float(b.frame))
    return abs(along) <= float(b.half_x) + 1e-9 and abs(across) <= float(b.half_y) + 1e-9


def rollout(network, seed, count=3):
    """``count`` highway-env traffic vehicles in a column on ``network``'s one lane, spawned as
    ``intersection-v2`` spawns them (speed 8 +- 1 m/s, their target; exponent drawn in its range),
    the first one slower: their measurements now and positions ``(STEPS+1, count, 2)``."""
    rng = np.random.default_rng(seed)
    road = Road(network=network, np_random=np.random.RandomState(seed))
    gaps = np.cumsum(rng.uniform(12.0, 30.0, count))
    road.vehicles = [
        Traffic(road, [100.0 + gap, 0.0], 0.0, float(rng.normal(8.0, 1.0) - (3.0 if k == count - 1 else 0.0)))
        for k, gap in enumerate(gaps)
    ]
    for v in road.vehicles:
        v.randomize_behavior()
    measurements = np.array([vehicle_measurement(v) for v in road.vehicles])
    positions = [np.array([v.position for v in road.vehicles])]
    for _ in range(STEPS):
        for _ in range(8):  # 16 Hz, as the env
            road.act()
            road.step(1 / 16)
        positions.append(np.array([v.position for v in road.vehicles]))
    return measurements, np.array(positions)


@pytest.mark.parametrize("seed", range(8))
def test_the_boxes_hold_highway_env_vehicles_with_sampled_parameters(straight, seed):
    measurements, positions = rollout(straight, seed)
    predictor = LanePredictor(straight, T, longitudinal="interval")
    mixtures = predictor.predict_scene(measurements, STEPS)
    for k, mixture in enumerate(mixtures):
        (mode,) = mixture.modes
        for n in range(STEPS + 1):
            assert inside(mode, n, positions[n, k]), (seed, k, n)


def test_the_interval_boxes_are_smaller_than_and_within_the_full_range_ones(env, straight):
    measurements, _ = rollout(straight, 0)
    full = LanePredictor(straight, T).predict_scene(measurements, STEPS)
    whole = IntervalModel(split_yield=False, centred=False)  # one box per route, about the mean
    interval = LanePredictor(straight, T, longitudinal="interval", intervals=whole).predict_scene(
        measurements, STEPS
    )
    for a, b in zip(full, interval, strict=True):
        wide, tight = a.modes[0].beliefs, b.modes[0].beliefs
        assert np.all(tight.x - tight.half_x >= wide.x - wide.half_x - 1e-9)
        assert np.all(tight.x + tight.half_x <= wide.x + wide.half_x + 1e-9)
        assert tight.half_x[STEPS] < 0.5 * wide.half_x[STEPS]
        assert np.all(tight.v_lo >= wide.v_lo - 1e-9) and np.all(tight.v_hi <= wide.v_hi + 1e-9)
    # the intersection's scene, turns included: with no turn margin every mode's box is no larger
    # than its full-range one; the turn margin widens it across a curving route only
    road = env.unwrapped.road
    scene = np.array([vehicle_measurement(v) for v in road.vehicles])
    full = LanePredictor(road.network, T).predict_scene(scene, STEPS)
    for margin in (0.0, IntervalModel().margin_turn):
        intervals = IntervalModel(margin_turn=margin, split_yield=False, centred=False)
        interval = LanePredictor(road.network, T, longitudinal="interval", intervals=intervals)
        for a, b in zip(full, interval.predict_scene(scene, STEPS), strict=True):
            assert [m.label for m in a] == [m.label for m in b]
            assert [m.weight for m in a] == pytest.approx([m.weight for m in b])
            for wide, tight in zip(a, b, strict=True):
                assert np.allclose(tight.beliefs.x, wide.beliefs.x) and np.allclose(
                    tight.beliefs.y, wide.beliefs.y
                )
                same = np.isclose(tight.beliefs.frame, wide.beliefs.frame)  # each box's frame: the smaller
                assert np.all((tight.beliefs.half_x <= wide.beliefs.half_x + 1e-6)[same])
                assert np.all((tight.beliefs.half_y <= wide.beliefs.half_y + margin + 1e-6)[same])
                if margin == 0.0:
                    area = 4 * tight.beliefs.half_x * tight.beliefs.half_y
                    assert np.all(area <= 4 * wide.beliefs.half_x * wide.beliefs.half_y + 1e-6)


def test_the_ego_takes_part_as_a_leader_and_is_not_predicted(straight):
    follower = np.array([100.0, 0.0, 0.0, 8.0, 0.0])
    ego = np.array([130.0, 0.0, 0.0, 0.0, 0.0])  # stopped ahead on the same lane
    alone = LanePredictor(straight, T, longitudinal="interval").predict_scene(follower[None], STEPS)
    seen = LanePredictor(straight, T, longitudinal="interval", ego=lambda: ego).predict_scene(
        follower[None], STEPS
    )
    assert len(seen) == 1  # the ego is in the scene, not in the output
    free, behind = alone[0].modes[0].beliefs, seen[0].modes[0].beliefs
    assert behind.x[STEPS] - behind.half_x[STEPS] < free.x[STEPS] - free.half_x[STEPS] - 3.0  # it may brake
    assert behind.x[STEPS] < min(ego[0], free.x[STEPS] - 2.0)  # its mean brakes behind the ego
    none = LanePredictor(straight, T, longitudinal="interval", ego=lambda: None).predict_scene(
        follower[None], STEPS
    )
    assert np.allclose(none[0].modes[0].beliefs.as_array(), free.as_array())


def test_the_name_reaches_the_adapter_and_the_benchmark(env):
    predictor = highway_predictor("lane+interval", env, pieces=2)
    assert predictor.name == "lane+interval" and predictor.longitudinal == "interval"
    assert predictor.pieces == 2 and predictor.max_modes == 6
    split = highway_predictor("lane+interval", env, intervals=IntervalModel(split_yield=True))
    assert split.max_modes == 6  # 3 turns, held and free
    assert np.allclose(predictor.ego(), vehicle_measurement(env.unwrapped.vehicle))
    assert highway_predictor("lane", env).name == "lane"
    args = highway_intersection.parse_args(["--predictor", "lane+interval", "--lane-pieces", "2"])
    assert args.predictor == ["lane+interval"]
    driver = make_driver(resolve("rmpc", "probability", 0.05), env, args, "lane+interval")
    built = driver._predictor_arg  # the adapter builds a named one at its first episode
    assert built.name == "lane+interval" and built.pieces == 2
    args = highway_intersection.parse_args(
        ["--predictor", "lane+interval", "--interval", "split_yield,centred"]
    )
    built = make_driver(resolve("rmpc", "probability", 0.05), env, args, "lane+interval")._predictor_arg
    assert built.intervals.split_yield and built.intervals.centred and built.pieces == 1
    with pytest.raises(ValueError, match="intervals need the predictor 'lane\\+interval'"):
        highway_predictor("lane", env, intervals=IntervalModel())


def test_bad_names_and_numbers_are_named(env, straight):
    with pytest.raises(ValueError, match="longitudinal"):
        LanePredictor(straight, T, longitudinal="full")
    with pytest.raises(ValueError, match="intervals and ego need longitudinal='interval'"):
        LanePredictor(straight, T, intervals=IntervalModel())
    with pytest.raises(TypeError, match="intervals must be an IntervalModel"):
        LanePredictor(straight, T, longitudinal="interval", intervals=(3.5, 4.5))
    with pytest.raises(TypeError, match="ego must be a callable"):
        LanePredictor(straight, T, longitudinal="interval", ego=np.zeros(5))
    with pytest.raises(ValueError, match="the ego's measurement"):
        LanePredictor(straight, T, longitudinal="interval", ego=lambda: [1.0, 2.0]).predict(np.zeros(5), 2)
    with pytest.raises(ValueError, match="IntervalModel.delta"):
        IntervalModel(delta=(4.5, 3.5))
    with pytest.raises(ValueError, match="IntervalModel.margin_rate"):
        IntervalModel(margin_rate=float("nan"))
    with pytest.raises(TypeError, match="IntervalModel.upper_yields"):
        IntervalModel(upper_yields=1)
    with pytest.raises(ValueError, match="predictor"):
        highway_predictor("lane+intervals", env)
    with pytest.raises(ValueError, match="longitudinal='interval'"):
        make_predictor("lane+interval", Scenario())
    with pytest.raises(SystemExit):
        highway_intersection.parse_args(["--predictor", "interval"])


def test_a_fitted_box_holds_its_stretch_of_a_turn_and_keeps_off_the_concentric_lane(env):
    from risk_env.highway.lanes.beliefs import Spread, mode_beliefs
    from risk_env.highway.lanes.routes import Route
    from risk_env.risk.disc import signed_box_distance

    network = env.unwrapped.road.network
    # the west road's right turn, concentric with the ego's left turn 4 m outside it
    turn = Route(network, (("o1", "ir1", 0), ("ir1", "il0", 0), ("il0", "o0", 0)))
    outer = Route(network, (("o0", "ir0", 0), ("ir0", "il1", 0)))
    start = float(network.get_lane(("o1", "ir1", 0)).length) - 8.0
    t = np.arange(STEPS + 1) * T
    s_lo, s_hi = start + 6.0 * t - 0.5 * t**2, start + 6.0 * t + 0.5 * t**2  # from 6 m/s, into the turn
    s = ((s_lo + s_hi) / 2)[None]
    bounds = (s_lo[None], s_hi[None], np.full((1, STEPS + 1), 4.0), np.full((1, STEPS + 1), 8.0))
    speeds = np.full_like(s, 6.0)
    args = (Spread(), turn, s, speeds, np.ones(1), start, 0.0, 6.0, T, 6.0, 1.0, (0, 1), bounds, 0.75, True)
    (fitted, held), (symmetric, _) = mode_beliefs(*args, True), mode_beliefs(*args, False)
    lane = outer.position(np.arange(outer.length * 0.2, outer.length, 0.25))
    clearance: dict[str, list[float]] = {}
    for name, b in (("fitted", fitted), ("symmetric", symmetric)):
        gaps = []
        for n in range(STEPS + 1):
            lo, hi = s_lo[n] - Spread().margin_along, s_hi[n] + Spread().margin_along
            stretch = turn.position(np.linspace(lo, hi, 50))
            dx, dy = to_frame(stretch[:, 0] - b.x[n], stretch[:, 1] - b.y[n], b.frame[n])
            assert np.all(np.abs(dx) <= b.half_x[n] + 1e-6) and np.all(np.abs(dy) <= b.half_y[n] + 1e-6), name
            # the stretch the gate may judge instead is the one the box holds
            dx, dy = to_frame(held.points[n, :, 0] - b.x[n], held.points[n, :, 1] - b.y[n], b.frame[n])
            assert np.all(np.abs(dx) <= b.half_x[n] + 1e-6) and np.all(np.abs(dy) <= b.half_y[n] + 1e-6), name
            dx, dy = to_frame(lane[:, 0] - b.x[n], lane[:, 1] - b.y[n], b.frame[n])
            gaps.append(float(np.min(signed_box_distance(dx, dy, b.half_x[n], b.half_y[n]))))
        clearance[name] = gaps
    assert np.all(fitted.half_x * fitted.half_y <= symmetric.half_x * symmetric.half_y + 1e-9)
    # the symmetric box bows out as far as the arc bows in, over the lane beside it (0.5 m from it at
    # 3 s); the fitted one never comes nearer, and at 3 s stays more than a metre farther off
    assert np.all(np.array(clearance["fitted"]) >= np.array(clearance["symmetric"]) - 1e-9)
    assert clearance["symmetric"][-1] < 1.0 and clearance["fitted"][-1] > clearance["symmetric"][-1] + 1.0


def test_every_interval_switch_of_the_benchmarks_is_a_switch_of_the_model():
    import dataclasses

    from benchmarks.highway_agents import INTERVAL_SWITCHES, interval_model, interval_switches

    fields = {f.name: f for f in dataclasses.fields(IntervalModel)}
    for name in INTERVAL_SWITCHES:
        assert fields[name].type in (bool, "bool") and fields[name].default is False
        on = interval_model((name,))
        assert getattr(on, name) is True
        assert all(getattr(on, other) == fields[other].default for other in fields if other != name)
    assert interval_switches("ego_ahead,upper_yields") == ("ego_ahead", "upper_yields")
