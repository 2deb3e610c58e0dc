"""highway-env integration: the wrapper's risk is our env's, the adapter drives intersection-v2, the
graphics draw headless. Checked against RiskCrossing-v0, highway-env's own lanes and kinematics."""

from __future__ import annotations

import functools
import math
import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("highway_env")

from agents import RMPC, SMPC  # noqa: E402
from risk_env import ENV_ID, observation  # noqa: E402
from risk_env.highway import (  # noqa: E402
    IDMEgo,
    IntersectionAdapter,
    RiskCostWrapper,
    RoutePath,
    highway_scenario,
    make_intersection_env,
    vehicle_measurement,
)
from risk_env.highway import graphics as G  # noqa: E402
from risk_env.models.dynamics import unicycle_step  # noqa: E402
from risk_env.models.ops import NUMPY  # noqa: E402
from risk_env.models.path import point  # noqa: E402
from risk_env.scenario.scenario import ReferencePath  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
KINEMATIC = {"action": {"type": "ContinuousAction", "dynamical": False}}


def highway(env_id: str, **config) -> gym.Env:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return gym.make(env_id, config=config)


def place(env: gym.Env, ego: tuple[float, ...], others: list[tuple[float, ...]]) -> None:
    """Replace the scene by kinematic vehicles at ``(x, y, heading, speed)``, no steering, no throttle."""
    from highway_env.vehicle.kinematics import Vehicle

    base = env.unwrapped
    road = base.road
    vehicles = [Vehicle(road, (x, y), heading, speed) for x, y, heading, speed in [ego, *others]]
    road.vehicles = vehicles
    base.controlled_vehicles = vehicles[:1]


# ------------------------------------------------------------------------------------ the wrapper
@pytest.mark.parametrize("estimator", ["exact", "worst_case"])
def test_wrapper_risk_equals_riskcrossing_risk(estimator):
    # The same state in both worlds: highway-fast-v0 with kinematic vehicles driving straight at
    # constant speed (highway-env's Euler steps are then exact) and RiskCrossing-v0 with the same
    # scenario, the ego at its action's speed and an object with turn rate 0.
    hw = RiskCostWrapper(highway("highway-fast-v0", **KINEMATIC), uncertainty="medium", estimator=estimator)
    assert hw.scenario.dt == 1.0  # highway-fast-v0: 5 frames at 5 Hz
    ego0, obj0, v_ego, v_obj = (200.0, 0.0, 0.0), (208.0, -10.0, math.pi / 2), 4.0, 3.0
    # the goal lies ahead of the ego, so that RiskCrossing-v0's episode does not end at once
    sc = hw.scenario.replace(
        ego_start=ego0, object_start=obj0, object_speed=v_obj, object_turn_rate=0.0, goal=(400.0, 0.0, 0.0)
    )
    hw = RiskCostWrapper(hw.env, scenario=sc, estimator=estimator)
    ours = gym.make(ENV_ID, scenario=sc, risk_estimator=estimator)
    ours.reset(seed=0)
    hw.reset(seed=0)
    place(hw, (*ego0[:2], ego0[2], v_ego), [(*obj0, v_obj)])
    hw.measure()
    risks = []
    for _ in range(2):
        _, _, _, _, info = ours.step(np.array([v_ego, 0.0], dtype=np.float32))
        _, _, _, _, hinfo = hw.step(np.zeros(2, dtype=np.float32))
        np.testing.assert_allclose(vehicle_measurement(hw.ego)[:4], info["ego"], atol=1e-9)
        np.testing.assert_allclose(hw.env.unwrapped.road.vehicles[1].position, info["object"][:2], atol=1e-9)
        assert hinfo["risk"] == pytest.approx(info["risk"], rel=1e-9, abs=1e-12)
        assert hinfo["cost"] == hinfo["risk"] and set(hinfo["risk_terms"]) == {1}
        assert hinfo["risk_violation"] == info["risk_violation"]
        risks.append(info["risk"])
    assert risks[0] == 0.0 and risks[1] > 1.0  # the object's box reaches the ego disc only at the second step


def test_wrapper_sums_terms_and_leaves_the_simulation_alone():
    # intersection-v1 as highway-env ships it (dynamic bicycle ego, IDM traffic). Monte Carlo draws
    # must come from the wrapper's generator: the simulation is the one without the wrapper.
    plain = highway("intersection-v1")
    wrapped = RiskCostWrapper(highway("intersection-v1"), uncertainty="high", estimator="monte_carlo")
    obs_a, _ = plain.reset(seed=3)
    obs_b, info = wrapped.reset(seed=3)
    assert info["risk"] == 0.0 and info["risk_terms"] == {}
    for _ in range(3):
        action = np.array([0.3, 0.05], dtype=np.float32)
        before = {id(v): v for v in wrapped.unwrapped.road.vehicles if v is not wrapped.ego}
        obs_a, *_ = plain.step(action)
        obs_b, _, _, _, info = wrapped.step(action)
        np.testing.assert_array_equal(obs_a, obs_b)
        vehicles = wrapped.unwrapped.road.vehicles
        assert info["risk"] == pytest.approx(sum(info["risk_terms"].values()))
        assert all(r >= 0.0 for r in info["risk_terms"].values())
        # one term per vehicle that was there before the step and still is, never the ego
        assert {id(vehicles[i]) for i in info["risk_terms"]} == {id(v) for v in vehicles if id(v) in before}
        assert info["risk_violation"] == (info["risk"] > wrapped.scenario.risk_tolerance)


def test_wrapper_rejects_bad_input():
    env = highway("highway-fast-v0")
    with pytest.raises(ValueError, match="unknown uncertainty preset 'huge'"):
        RiskCostWrapper(env, uncertainty="huge")
    with pytest.raises(ValueError, match="unknown risk estimator 'magic'"):
        RiskCostWrapper(env, estimator="magic")
    with pytest.raises(TypeError, match="unknown scenario parameter"):
        RiskCostWrapper(env, ego_radios=2.0)
    with pytest.raises(TypeError, match="without controlled_vehicles"):
        RiskCostWrapper(gym.make(ENV_ID))
    with pytest.raises(TypeError, match="not both"):
        RiskCostWrapper(env, scenario=highway_scenario(env), ego_radius=2.0)
    wrapper = RiskCostWrapper(env)
    wrapper.reset(seed=0)
    env.unwrapped.controlled_vehicles = []
    with pytest.raises(ValueError, match="controlled vehicle"):
        wrapper.step(0)


# ------------------------------------------------------------------------------------ measurement
@pytest.mark.parametrize("steering", [0.0, 0.15, -0.3])
def test_vehicle_measurement_predicts_highway_env_motion(steering):
    # Our unicycle from vehicle_measurement moves the centre as highway-env's kinematic bicycle
    # does (up to its 15 Hz Euler steps), heading and direction of travel exactly.
    env = highway("intersection-v1", **KINEMATIC)
    env.reset(seed=0)
    place(env, (0.0, 30.0, -1.0, 7.0), [])
    vehicle = env.unwrapped.vehicle
    vehicle.action = {"steering": steering, "acceleration": 0.0}
    m = vehicle_measurement(vehicle)
    dt = 1.0
    for _ in range(15):
        vehicle.step(dt / 15)
    x, y, theta = unicycle_step(*m, dt, NUMPY)
    after = vehicle_measurement(vehicle)
    assert after[2] == pytest.approx(float(theta), abs=1e-9)
    assert np.hypot(after[0] - x, after[1] - y) < 0.02 + 0.5 * abs(m[3] * m[4]) * dt * dt / 15


# ------------------------------------------------------------------------------------ the route
def test_route_and_lanes_are_the_same_curves():
    env = make_intersection_env()
    env.reset(seed=0)
    network = env.unwrapped.road.network
    route = RoutePath.of_vehicle(network, env.unwrapped.vehicle, "o1")
    assert route.lanes == (("o0", "ir0", 0), ("ir0", "il1", 0), ("il1", "o1", 0))
    # the left turn (on screen) has radius 13 m; highway-env's y points down, so its heading decreases
    assert route.paths[1].curvature == pytest.approx(-1 / 13.0)
    for index, offset, path in zip(route.lanes, route.offsets, route.paths, strict=True):
        lane = network.get_lane(index)
        s = np.linspace(0.0, lane.length, 7)
        expected = np.array([lane.position(si, 0.0) for si in s])
        np.testing.assert_allclose(route.position(offset + s), expected, atol=1e-6)
        theta = point(path, s + path.lambda_start)[2]
        np.testing.assert_allclose(np.cos(theta), np.cos([lane.heading_at(si) for si in s]), atol=1e-9)
    from highway_env.road.lane import SineLane

    with pytest.raises(ValueError, match="straight and circular lanes only"):
        RoutePath.from_lanes(_Network(SineLane([0, 0], [10, 0], 1.0, 0.1, 0.0)), [("a", "b", 0)])


class _Network:
    def __init__(self, lane):
        self.lane = lane

    def get_lane(self, index):
        return self.lane


@pytest.mark.parametrize("curvature", [0.003, -0.05, 0.0])
def test_arc_lane_is_our_arc(curvature):
    path = ReferencePath(goal=(65.0, 5.0, 0.3), curvature=curvature, lambda_start=-40.0)
    x, y, theta = point(path, path.lambda_start)
    lane = G.arc_lane(x, y, theta, curvature, 40.0)
    lam = np.linspace(path.lambda_start, 0.0, 9)
    ours = np.column_stack(point(path, lam)[:2])
    theirs = np.array([lane.position(s, 0.0) for s in lam - path.lambda_start])
    np.testing.assert_allclose(theirs, ours, atol=1e-9)
    assert lane.length == pytest.approx(40.0)
    np.testing.assert_allclose(
        np.cos([lane.heading_at(s) for s in lam - path.lambda_start]), np.cos(point(path, lam)[2])
    )


# ------------------------------------------------------------------------------------ the adapter
def test_adapter_drives_intersection_v2_with_every_vehicle():
    env = RiskCostWrapper(make_intersection_env(), ego_radius=2.0, object_radius=2.0)
    assert env.unwrapped.spec.id == "intersection-v2"
    # the junction gate off: every slot goes to a vehicle (tests/test_gate.py checks the gate's slot)
    adapter = IntersectionAdapter(env, functools.partial(RMPC, max_solve_time=math.inf), slots=3, gate=False)
    obs, _ = env.reset(seed=1)
    vehicle = env.unwrapped.vehicle
    assert adapter.last_solve is None
    with pytest.raises(ValueError, match="no route yet"):
        adapter.scenario  # noqa: B018
    for _ in range(5):
        action, state = adapter.predict(obs)
        assert state is None and action.shape == (2,) and action.dtype == np.float32
        assert np.all(np.abs(action) <= 1.0)
        assert adapter.agent.slots == 3
        ours = adapter.last_observation
        assert ours.shape == (observation.size(3),) and np.all(np.isfinite(ours))
        split = observation.split(ours, slots=3)
        # every observed vehicle, nearest first, up to the slot count; the rest flagged absent
        others = [v for v in env.unwrapped.road.vehicles if v is not vehicle]
        m = len(adapter.last_objects)
        assert m == min(3, int(np.sum(obs[1:, 0] > 0.5))) and split.present.sum() == m
        assert not split.present[m:].any() and np.all(split.objects[m:] == 0.0)
        gaps = np.hypot(*(adapter.last_objects[:, :2] - vehicle.position).T)
        assert np.all(np.diff(gaps) >= -1e-6)
        for o in adapter.last_objects:
            assert min(np.hypot(*(v.position - o[:2])) for v in others) < 1e-4
        report = adapter.last_solve
        assert report is not None and report.solve_time > 0
        obs, _, terminated, truncated, info = env.step(action)
        # the speed asked for is reached at the end of the step (no saturation at these speeds)
        assert vehicle.speed == pytest.approx(float(report.action[0]), abs=1e-6)
        assert "risk" in info
        if terminated or truncated:
            break
    assert adapter.route.lanes[0] == ("o0", "ir0", 0)
    with pytest.raises(ValueError, match="slots must be an integer >= 1"):
        IntersectionAdapter(env, RMPC, slots=0)


def test_intersection_v1_stays_selectable():
    env = make_intersection_env(version="intersection-v1")
    assert env.unwrapped.spec.id == "intersection-v1"
    with pytest.raises(ValueError, match="unknown intersection 'intersection-v3'"):
        make_intersection_env(version="intersection-v3")


def test_crash_kind_from_the_closing_speeds():
    from types import SimpleNamespace

    from benchmarks.highway_episodes import crash_kind

    ego = SimpleNamespace(position=np.array([0.0, 0.0]), crashed=True)
    other = SimpleNamespace(position=np.array([4.0, 0.0]), crashed=True)
    base = SimpleNamespace(vehicle=ego, road=SimpleNamespace(vehicles=[ego, other]))
    moving, still = (np.zeros(2), np.array([5.0, 0.0])), (np.zeros(2), np.zeros(2))
    # the ego drives at 5 m/s into a standing vehicle ahead; then a vehicle rear-ends a stopped ego
    assert crash_kind(base, {id(ego): moving, id(other): (np.array([4.0, 0.0]), np.zeros(2))}) == "ego"
    behind = {id(ego): still, id(other): (np.array([4.0, 0.0]), np.array([-6.0, 0.0]))}
    assert crash_kind(base, behind) == "other"
    # a standing ego drove into nothing, even where the vehicle's centre moves away (its front
    # swinging into the ego as it reverses along a curve: highway-env's IDM overshoots below 0 m/s)
    away = {id(ego): still, id(other): (np.array([4.0, 0.0]), np.array([3.0, 1.0]))}
    assert crash_kind(base, away) == "other"
    creeping = (np.zeros(2), np.array([0.5, 0.0]))
    assert crash_kind(base, {id(ego): creeping, id(other): away[id(other)]}) == "ego"


def test_adapter_turn_rate_and_speed_translation():
    # highway_action's steering ends the step at the heading the unicycle predicts.
    env = make_intersection_env()
    env.reset(seed=0)
    place(env, (2.0, 40.0, -math.pi / 2, 8.0), [])
    adapter = IntersectionAdapter(env, RMPC)
    vehicle, steering = env.unwrapped.vehicle, 0.0
    for v, omega in ((8.5, 0.4), (7.5, 0.7), (7.0, -0.2)):
        start = vehicle_measurement(vehicle)
        action, steering = adapter.highway_action(v, omega, vehicle.speed, steering)
        env.step(action)
        end = vehicle_measurement(vehicle)
        assert end[3] == pytest.approx(v, abs=1e-9)
        assert end[2] - start[2] == pytest.approx(omega * adapter.dt, abs=0.02)


def test_a_standing_car_keeps_its_wheels_straight():
    # a turn rate asked of a car that stands (and stays so) sets no steering: its direction of travel
    # stays its body's heading; asked to move off, it steers as before
    env = make_intersection_env()
    env.reset(seed=0)
    place(env, (2.0, 40.0, -math.pi / 2, 0.0), [])
    adapter = IntersectionAdapter(env, RMPC)
    vehicle = env.unwrapped.vehicle
    action, steering = adapter.highway_action(0.0, 0.8, 0.0, 0.5)
    assert steering == 0.0 and action[1] == pytest.approx(0.0, abs=1e-6)
    env.step(action)
    assert vehicle_measurement(vehicle)[2] == pytest.approx(vehicle.heading, abs=1e-9)
    _, steering = adapter.highway_action(2.0, 0.8, 0.0, 0.0)
    assert steering > 0.1


@pytest.mark.slow  # its NLPs (two slots of the lane predictor's modes) are the costliest to build here
def test_smpc_in_intersection():
    """The exact SMPC through the adapter with its default (lane) predictor. The default run covers
    the parts: the adapter with an SMPC (test_an_episode_records_every_column in
    tests/test_highway_benchmark.py), with the lane predictor (the README's intersection block and
    test_lane_pieces_reach_the_mpcs_predictor_and_size_their_mode_slots, with the RMPC), and the SMPC
    on a predictor's weighted modes (tests/test_mixture_planning.py)."""
    env = make_intersection_env()
    uncapped = functools.partial(SMPC, risk="exact", max_solve_time=math.inf)  # a busy machine: no fallback
    smpc = IntersectionAdapter(env, uncapped, risk_tolerance=500.0, slots=2)
    obs, _ = env.reset(seed=2)
    for _ in range(2):
        action, _ = smpc.predict(obs)
        obs, *_ = env.step(action)
    assert smpc.last_solve.success


def test_idm_in_intersection():
    env = make_intersection_env()
    idm = IDMEgo(env)
    obs, _ = env.reset(seed=2)
    idm.predict(obs)
    from highway_env.vehicle.behavior import IDMVehicle

    assert (
        isinstance(env.unwrapped.vehicle, IDMVehicle) and env.unwrapped.vehicle in env.unwrapped.road.vehicles
    )
    assert env.unwrapped.vehicle.route[-1][1] == "o1"
    start = env.unwrapped.vehicle.position.copy()
    env.step(idm.predict(obs)[0])
    assert np.hypot(*(env.unwrapped.vehicle.position - start)) > 1.0  # it drives itself


def test_adapter_rejects_highway_env_defaults():
    with pytest.raises(ValueError, match="make_intersection_env"):
        IntersectionAdapter(highway("intersection-v1"), RMPC)  # dynamic bicycle, normalised obs
    with pytest.raises(ValueError, match="unknown uncertainty preset"):
        IntersectionAdapter(make_intersection_env(), RMPC, uncertainty="extreme")
    with pytest.raises(TypeError, match="without controlled_vehicles"):
        IntersectionAdapter(gym.make(ENV_ID), RMPC)


# ------------------------------------------------------------------------------------ graphics
def frame_has(frame: np.ndarray, colour: tuple[int, ...]) -> bool:
    return bool(np.any(np.all(frame == np.array(colour[:3], dtype=np.uint8), axis=-1)))


def test_highway_renderer_draws_the_scene_headless():
    env = gym.make(ENV_ID, render_mode="rgb_array", renderer="highway", uncertainty="medium")
    env.reset(seed=0)
    for _ in range(4):
        env.step(np.array([3.0, 0.0], dtype=np.float32))
    frame = env.render()
    renderer = env.unwrapped._view._renderer
    assert isinstance(renderer, G.HighwayRenderer)
    assert frame.shape == (450, 800, 3) and frame.dtype == np.uint8
    for (x, y), colour in (
        (env.unwrapped._ego_pose[:2], G.EGO),
        (env.unwrapped.object_measurement[:2], G.OBJECT),
    ):
        u, w = np.round(renderer._to_px(x + 0.5, y)).astype(int)  # on the car's body, off its disc
        assert tuple(frame[w, u]) == colour
    assert frame_has(frame, G.BOX_NEAR) and not frame_has(frame, G.PLAN) and not frame_has(frame, G.SAMPLE)
    env.unwrapped.set_plan(np.column_stack([np.linspace(-5.0, 10.0, 6), np.full(6, 12.0)]))
    assert frame_has(env.render(), G.PLAN)
    auto = gym.make(ENV_ID, render_mode="rgb_array")
    auto.reset()
    auto.render()
    assert isinstance(auto.unwrapped._view._renderer, G.HighwayRenderer)
    with pytest.raises(ValueError, match="unknown renderer 'fancy'"):
        gym.make(ENV_ID, renderer="fancy")


def test_highway_renderer_draws_every_object():
    env = gym.make(ENV_ID, render_mode="rgb_array", renderer="highway", scene="two_crossing")
    env.reset(seed=0)
    env.step(np.array([2.0, 0.0], dtype=np.float32))
    frame = env.render()
    renderer = env.unwrapped._view._renderer
    assert len(renderer._objects) == 2
    for x, y, *_ in env.unwrapped.object_measurements:
        u, w = np.round(renderer._to_px(x + 0.5, y)).astype(int)
        assert tuple(frame[w, u]) == G.OBJECT


def test_monte_carlo_draws_are_drawn_and_seeded():
    frames = []
    for _ in range(2):
        env = gym.make(ENV_ID, render_mode="rgb_array", renderer="highway", risk_estimator="monte_carlo")
        env.reset(seed=0)
        env.step(np.array([2.0, 0.0], dtype=np.float32))
        frames.append(env.render())
    assert frame_has(frames[0], G.SAMPLE)
    np.testing.assert_array_equal(frames[0], frames[1])  # the renderer's own seeded generator


def test_highway_human_mode_and_scene_frames():
    env = gym.make(ENV_ID, render_mode="human", renderer="highway")
    env.reset(seed=0)  # renders itself under the dummy driver
    assert env.render() is None
    env.close()
    hw = make_intersection_env()
    hw.reset(seed=0)
    frame = G.render_scene(hw, route=np.array([[2.0, 40.0], [2.0, 0.0]]), status=("hello",))
    assert frame.shape == (600, 600, 3) and frame.std() > 5.0
    assert frame_has(frame, G.EGO) and frame_has(frame, G.ROUTE)
    assert not hasattr(hw.unwrapped.vehicle, "color")  # the ego's colour was restored


def test_import_without_highway_env_keeps_risk_env_working():
    script = textwrap.dedent(
        """
        import sys
        sys.modules["highway_env"] = None  # as if it were not installed
        import gymnasium as gym, numpy as np, risk_env
        env = gym.make("RiskCrossing-v0", render_mode="rgb_array")
        env.reset(seed=0)
        assert env.render().ndim == 3
        print(type(env.unwrapped._view._renderer).__name__)
        try:
            import risk_env.highway
        except ImportError as err:
            print(err)
        """
    )
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy", "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    renderer, message = out.stdout.splitlines()[:2]
    assert renderer == "Renderer"  # "auto" fell back to the basic view
    assert "pip install 'riskcrossing[render]'" in message


# ------------------------------------------------------------------------------------ benchmarks
def test_highway_benchmarks_run_small(tmp_path):
    from PIL import Image

    from benchmarks import highway_intersection, highway_render

    tiny = ["--episodes", "1", "--duration", "3", "--predictor", "constant", "--workers", "1"]
    tiny += ["--max-solve-time", "inf", "--slots", "1"]  # the smallest MPC: the plumbing is the point
    tiny += ["--initial-vehicles", "3"]  # and a light intersection (highway-env's steps are the cost)
    summary = highway_intersection.main([*tiny, "--agents", "rmpc,idm", "--out", str(tmp_path)])
    assert [s["agent"] for s in summary] == ["rmpc:worst_case", "idm"]
    for s in summary:
        assert s["episodes"] == 1 and s["collision_rate"] + s["goal_rate"] + s[
            "timeout_rate"
        ] == pytest.approx(1.0)
        assert s["ego_into_vehicle"] + s["vehicle_into_ego"] == s["collision"]
    assert np.isfinite(summary[0]["solve_ms_median"]) and np.isnan(summary[1]["solve_ms_median"])
    for name in ("intersection.md", "intersection.csv", "intersection_episodes.csv"):
        assert (tmp_path / name).stat().st_size > 0
    written = highway_render.main(["--out", str(tmp_path), "--max-steps", "3"])
    with Image.open(written[0]) as gif:
        assert gif.n_frames == 4 and gif.size == (800, 450)
