r"""A car turns only while it moves: the ego's curvature limit $|\omega| \le \kappa_{max} v$ in the
MPC's rows, its fallback, the env's dynamics and the intersection adapter's car."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import risk_env  # noqa: F401  (registers the env)
from agents import RMPC
from agents.mpc import fallback
from agents.mpc.nlp.corridor import step_widths, turn_back
from risk_env.models.dynamics import turn_limit
from risk_env.models.path import point
from risk_env.scenario.scenario import Scenario

KAPPA = 0.2
"""[1/m]: a turning circle of 5 m."""


def standing_askew(curvature: float) -> Scenario:
    """The paper's low scene with the ego standing 0.4 rad off its path's heading, no reversing."""
    base = Scenario.preset("low")
    start = (base.ego.start.x, base.ego.start.y, base.ego.start.theta + 0.4)
    return base.replace(v_min=0.0, ego_start=start, curvature_max=curvature)


def planned(scenario: Scenario) -> tuple[np.ndarray, RMPC]:
    """The first plan's inputs ``(N, 2)`` from the env's start, and the agent."""
    agent = RMPC(scenario, max_solve_time=math.inf)
    obs, _ = gym.make("RiskCrossing-v0", scenario=scenario).reset(seed=0)
    agent.predict(obs)
    return agent.last_solve.inputs, agent


def test_the_plan_turns_only_while_it_moves_and_the_paper_has_no_such_rows():
    r"""From a standstill askew, the unicycle turns at once, faster than a car can at that speed;
    with the limit every planned input keeps $|\omega_n| \le \kappa v_n$."""
    unlimited, paper = planned(standing_askew(math.inf))
    assert np.any(np.abs(unlimited[:, 1]) > KAPPA * unlimited[:, 0] + 1e-2)  # the limit binds here
    assert not any(tag[1] == "curvature" for tag in paper._problem(paper.last_solve.variant).g_tags)
    inputs, agent = planned(standing_askew(KAPPA))
    assert agent.last_solve.fallback is None
    assert np.all(np.abs(inputs[:, 1]) <= KAPPA * inputs[:, 0] + 1e-6)
    rows = [tag for tag in agent._problem(agent.last_solve.variant).g_tags if tag[1] == "curvature"]
    assert len(rows) == 2 * agent.scenario.horizon
    assert inputs[-1, 0] > 2.0  # it drives off and turns, rather than standing


@settings(max_examples=80, deadline=None)
@given(
    v_last=st.floats(0.0, 8.0),
    share=st.floats(-1.0, 1.0),
    action=st.tuples(st.floats(-4.0, 10.0), st.floats(-1.0, 1.0)),
)
def test_the_fallback_keeps_the_limit(v_last, share, action):
    r"""The clip of an input and every manoeuvre of the family keep $|\omega| \le \kappa v$ from
    any last input that kept it."""
    scenario = standing_askew(KAPPA)
    last = np.array([v_last, share * min(KAPPA * v_last, scenario.ego.omega_max)])
    v, w = fallback.feasible_action(scenario, np.array(action), last)
    assert abs(w) <= KAPPA * v + 1e-12
    x0 = np.array([0.0, 0.0, 0.0, -90.0, *last])
    for inputs in fallback.manoeuvres(scenario, x0).values():
        assert np.all(np.abs(inputs[:, 1]) <= KAPPA * inputs[:, 0] + 1e-12)


def test_the_env_turns_the_car_only_while_it_moves():
    r"""The single and the batched env apply $\omega$ within $\kappa v$; without a limit the unicycle
    turns standing, as in the paper."""
    for curvature, turned in ((KAPPA, 0.0), (math.inf, 0.5 * 0.5)):
        scenario = standing_askew(curvature)
        env = gym.make("RiskCrossing-v0", scenario=scenario)
        obs, _ = env.reset(seed=0)
        heading = env.unwrapped._ego_pose[2]
        env.step(np.array([0.0, 0.5], dtype=np.float32))
        assert env.unwrapped._ego_pose[2] - heading == pytest.approx(turned, abs=1e-6)
    scenario = standing_askew(KAPPA)
    batched = gym.make_vec("RiskCrossing-v0", num_envs=9, scenario=scenario).unwrapped
    batched.reset(seed=0)
    before = batched._state[2].copy()
    batched.step(np.tile([2.0, 0.8], (9, 1)).astype(np.float32))  # at 2 m/s the limit is 0.4 rad/s
    assert np.allclose(batched._state[2] - before, KAPPA * 2.0 * scenario.dt, atol=1e-6)


def test_car_turning_gives_the_adapters_agents_the_cars_turning_circle():
    r"""highway-env's kinematic bicycle at full lock (60 degrees in the adapter's config) turns its
    course at $v \sin\beta / (l / 2)$; ``--car-turning`` hands that to the adapter's scenario,
    whose default stays the paper's unicycle."""
    from benchmarks.highway_agents import ego_overrides
    from benchmarks.highway_intersection import parse_args
    from risk_env.highway import IntersectionAdapter, make_intersection_env
    from risk_env.highway.common import bicycle_curvature

    env = make_intersection_env()
    expected = math.sin(math.atan(0.5 * math.tan(math.pi / 3))) / 2.5
    assert bicycle_curvature(env.unwrapped) == pytest.approx(expected)
    overrides = ego_overrides(parse_args(["--car-turning"]), env)
    assert overrides["curvature_max"] == pytest.approx(expected)
    assert "curvature_max" not in ego_overrides(parse_args([]), env)
    adapter = IntersectionAdapter(env, RMPC, predictor=None, gate=False, warm_up=False, **overrides)
    assert adapter.base_scenario.ego.curvature_max == pytest.approx(expected)
    plain = IntersectionAdapter(env, RMPC, predictor=None, gate=False, warm_up=False)
    assert plain.base_scenario.ego.curvature_max == math.inf


def test_turn_limit_clips_into_the_cone():
    omega = np.array([-1.0, -0.1, 0.0, 0.3, 1.0])
    v = np.array([1.0, 0.0, 3.0, 1.0, 10.0])
    assert np.allclose(turn_limit(KAPPA, omega, v), [-0.2, 0.0, 0.0, 0.2, 1.0])
    assert turn_limit(math.inf, omega, v) is omega


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, -math.inf])
def test_a_bad_curvature_is_named(bad):
    with pytest.raises(ValueError, match="ego.curvature_max"):
        Scenario.preset("low").replace(v_min=0.0, curvature_max=bad)
    with pytest.raises(TypeError, match="ego.curvature_max"):
        Scenario.preset("low").replace(v_min=0.0, curvature_max="1")


def test_a_curvature_limit_refuses_a_reversing_ego():
    with pytest.raises(ValueError, match="v_min >= 0"):
        Scenario.preset("low").replace(curvature_max=KAPPA)


def test_an_ego_heading_out_of_its_corridor_gets_room_to_turn_back():
    r"""Near the corridor's edge heading 30 degrees outwards, a car drifts $R (1 - \cos 30^\circ)$ further
    out before it is parallel again: the step's corridor (hard, soft, free) leaves it that much room, and
    narrows to where it is now, never further out; heading inwards, or turning standing, it does not."""
    base = standing_askew(KAPPA).replace(corridor=1.0)
    path = base.path
    lam = path.lambda_start + 10.0
    x, y, theta = point(path, lam)
    normal = np.array([-math.sin(theta), math.cos(theta)])
    px, py = np.array([x, y]) + 0.9 * normal  # near the left edge
    out = theta + math.radians(30.0)  # turned left: outwards
    drift = (1.0 - math.cos(math.radians(30.0))) / KAPPA
    assert turn_back(base, 0.9, px, py, out) == pytest.approx(drift)
    assert turn_back(base, 0.9, px, py, theta - 0.5) == 0.0  # inwards
    assert turn_back(base.replace(v_min=-4.0, curvature_max=math.inf), 0.9, px, py, out) == 0.0
    N = base.horizon
    for soft, free in ((False, False), (True, False), (False, True)):
        width = step_widths(base, px, py, soft, free, 0.5, out)
        assert width[0] >= 0.9 + drift and width[-1] == pytest.approx(1.0)
        assert np.all(np.diff(width) <= 0.0) and len(width) == N
    assert np.all(step_widths(base, px, py, False, False, 0.5, theta - 0.5) == 1.0)
