"""A standing plan restarted from cold (``restart_standing``): where the ego and its last plan stand,
a step also solves from the cold starts and keeps the cheaper plan."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import risk_env  # noqa: F401  (registers the env)
from agents import RMPC
from agents.mpc.attempts import STANDING, stands
from risk_env import observation as ob
from risk_env.scenario.scenario import Scenario


def askew_at_the_edge() -> Scenario:
    """The paper's low scene with a car-like ego (turning circle 5 m) standing 0.9 m left of its path
    in a 1 m corridor, heading 0.5 rad further out: it can only drive out before it turns back."""
    base = Scenario.preset("low")
    x, y, theta = base.ego.start.x, base.ego.start.y, base.ego.start.theta
    start = (x - 0.9 * math.sin(theta), y + 0.9 * math.cos(theta), theta + 0.5)
    return base.replace(v_min=0.0, ego_start=start, curvature_max=0.2, corridor=1.0)


def replanned_from_standing(restart: bool) -> tuple[RMPC, float, float]:
    """``(agent, cost of its first plan, cost of the plan from a standing warm start)``: the second
    step sees the same observation with the last plan replaced by one that stands."""
    scenario = askew_at_the_edge()
    agent = RMPC(scenario, max_solve_time=math.inf, restart_standing=restart)
    obs, _ = gym.make("RiskCrossing-v0", scenario=scenario).reset(seed=0)
    agent.predict(obs)
    first = agent.last_solve.cost
    memory, o = agent._memory[0], ob.split(obs, slots=agent.slots)
    standing = np.zeros_like(memory["plan"])
    memory.update(plan=standing, lam_x=None, action=o.ego_input.copy(), predicted=o.ego_pose[:2].copy())
    agent.predict(obs)
    return agent, first, agent.last_solve.cost


def test_a_standing_warm_start_is_restarted_from_cold():
    """Without the restart the solver, warm-started from standing, ends in a costlier plan that stops
    again; with it the step finds the cold start's plan."""
    agent, first, warm = replanned_from_standing(restart=False)
    assert warm > first * 1.01 and agent.last_solve.inputs[-1, 0] < STANDING
    agent, first, restarted = replanned_from_standing(restart=True)
    assert agent.last_solve.fallback is None
    assert restarted == pytest.approx(first, rel=1e-3)
    assert agent.last_solve.inputs[-1, 0] > 1.0  # it drives on


def test_only_a_standing_ego_on_a_standing_plan_restarts():
    plan = np.zeros((6, 3))
    moving = plan.copy()
    moving[3, 0] = 2.0
    x0 = np.zeros(6)
    assert stands(True, {"plan": plan}, x0)
    assert not stands(False, {"plan": plan}, x0)  # the agent's switch
    assert not stands(True, None, x0)  # a new episode
    assert not stands(True, {"plan": None}, x0)
    assert not stands(True, {"plan": moving}, x0)
    rolling = x0.copy()
    rolling[4] = 1.0
    assert not stands(True, {"plan": plan}, rolling)


def test_the_switch_is_off_by_default_and_reaches_the_settings():
    scenario = Scenario.preset("low", horizon=3)
    assert not RMPC(scenario).settings.restart_standing
    assert RMPC(scenario, restart_standing=True).settings.restart_standing
