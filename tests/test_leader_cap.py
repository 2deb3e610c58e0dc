"""The leader cap (:attr:`GateSettings.leader_cap <risk_env.highway.gate_judge.GateSettings.leader_cap>`):
the reference and applied speeds from which the approach braking stops the ego behind the road user
ahead on its route."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("highway_env")

from highway_helpers import LEFT_TURN, measurement  # noqa: E402

from risk_env.highway import IntersectionAdapter, make_intersection_env  # noqa: E402
from risk_env.highway.gate_judge import GateSettings  # noqa: E402
from risk_env.highway.lanes.follow import (  # noqa: E402
    LEADER_BRAKING,
    LEADER_MARGIN,
    leader_gap,
    leader_speed,
)
from risk_env.highway.lanes.routes import Route  # noqa: E402

LENGTH = 5.0


def test_the_gap_is_to_the_nearest_road_user_ahead_on_the_route(network):
    route = Route(network, LEFT_TURN)
    ego = tuple(measurement(network, LEFT_TURN[0], 50.0, 5.0)[:2])
    ahead = measurement(network, LEFT_TURN[0], 70.0, 4.0)
    further = measurement(network, LEFT_TURN[0], 90.0, 8.0)
    behind = measurement(network, LEFT_TURN[0], 30.0, 8.0)
    beside = measurement(network, ("il0", "o0", 0), 50.0, 8.0)  # the exit beside, the other way
    gap = leader_gap(route, ego, np.array([further, behind, beside, ahead]), LENGTH)
    assert gap == pytest.approx((20.0 - LENGTH - LEADER_MARGIN, 4.0))
    assert leader_gap(route, ego, np.array([behind, beside]), LENGTH) is None
    assert leader_gap(route, ego, np.zeros((0, 5)), LENGTH) is None
    askew = measurement(network, LEFT_TURN[0], 70.0, 4.0, turn=0.5)  # its speed along the route
    assert leader_gap(route, ego, askew[None], LENGTH)[1] == pytest.approx(4.0 * math.cos(0.5))
    rolling_back = measurement(network, LEFT_TURN[0], 70.0, -1.0)
    assert leader_gap(route, ego, rolling_back[None], LENGTH)[1] == 0.0
    # on the exit after the turn: along the route's arc length
    exit_car = measurement(network, LEFT_TURN[2], 10.0, 0.0)
    ego_turning = tuple(measurement(network, LEFT_TURN[1], 5.0, 5.0)[:2])
    room, _ = leader_gap(route, ego_turning, exit_car[None], LENGTH)
    length = network.get_lane(LEFT_TURN[1]).length
    assert room == pytest.approx(length - 5.0 + 10.0 - LENGTH - LEADER_MARGIN, abs=0.3)


def test_the_speed_stops_the_ego_within_the_gap_and_the_leaders_braking():
    assert leader_speed(None, 1.5) == math.inf
    assert leader_speed((6.0, 0.0), 1.5) == pytest.approx(math.sqrt(2 * 1.5 * 6.0))
    v_l = 6.0
    assert leader_speed((6.0, v_l), 1.5) == pytest.approx(
        math.sqrt(2 * 1.5 * (6.0 + v_l**2 / (2 * LEADER_BRAKING)))
    )
    assert leader_speed((-3.0, 0.0), 1.5) == 0.0  # closer than the margin: stop
    # from that speed, braking at b, the ego stops within the room plus the leader's braking distance
    for room, v_l in ((0.0, 3.0), (4.0, 0.0), (12.0, 8.0)):
        v = leader_speed((room, v_l), 2.0)
        assert v**2 / (2 * 2.0) == pytest.approx(room + v_l**2 / (2 * LEADER_BRAKING))


class Recorder:
    """An agent that asks for 10 m/s straight on and records its speed limit."""

    def __init__(self, scenario, object_slots, predictor=None):
        self.speed_limit, self.seen = np.inf, []

    def predict(self, obs, episode_start=None, deterministic=True):
        self.seen.append(self.speed_limit)
        return np.array([10.0, 0.0]), None


@pytest.mark.parametrize("seed", [3, 7])
def test_the_adapter_caps_the_reference_and_the_applied_speed_behind_a_leader(seed):
    """Driving a few steps of a seed with a car ahead on the ego's route: the agent's limit is the
    cap, and the action applied is the one for the agent's speed capped so."""
    env = make_intersection_env()
    settings = GateSettings(leader_cap=True)
    adapter = IntersectionAdapter(env, Recorder, slots=3, predictor="lane+interval", gate=settings)
    plain = IntersectionAdapter(env, Recorder, slots=3, predictor="lane+interval", gate=GateSettings())
    obs, _ = env.reset(seed=seed)
    adapter.reset()
    capped = 0
    for _ in range(10):
        ego = env.unwrapped.vehicle
        x, y, speed, steering = *(float(c) for c in ego.position), float(ego.speed), adapter._steering
        action = adapter.predict(obs)[0]
        gap = leader_gap(adapter._leader_route, (x, y), adapter._tracks, float(ego.LENGTH))
        expected = leader_speed(gap, adapter.gate.approach_braking * adapter.gate.accel)
        limit = adapter._agent_for(adapter.lane).seen[-1]
        assert limit == pytest.approx(min(expected, adapter.gate.stop_speed()))
        applied = plain.highway_action(min(10.0, expected), 0.0, speed, steering)[0]
        assert np.allclose(action, applied, atol=1e-5)  # the observation is float32
        capped += expected < 10.0
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    assert capped


def test_the_cap_is_a_gate_setting_of_the_benchmark():
    from benchmarks import highway_intersection
    from benchmarks.highway_agents import gate_settings

    args = highway_intersection.parse_args(["--gate-leader-cap"])
    assert gate_settings(args) == GateSettings(leader_cap=True)
    assert gate_settings(highway_intersection.parse_args([])) == GateSettings()
