"""An MPC's speed limit (PathFollowingMPC.speed_limit): a cap on v_ref from the next step on (the
junction gate's slow approach sets it each step); validated, and it slows the plan."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import risk_env  # noqa: F401  (registers RiskCrossing-v0)
from agents import RMPC
from risk_env.scenario.scenario import Scenario


def test_the_speed_limit_caps_v_ref_and_slows_the_plan():
    scenario = Scenario.preset("low")
    agent = RMPC(scenario, max_solve_time=math.inf)
    obs, _ = gym.make("RiskCrossing-v0", scenario=scenario).reset(seed=0)
    assert agent.speed_limit == math.inf
    assert agent._measure(0, obs).p[1] == scenario.ego.v_ref
    agent.predict(obs)
    free = agent.last_solve.ego_trajectory
    agent.reset()
    agent.speed_limit = 1.0
    assert agent._measure(0, obs).p[1] == 1.0
    agent.predict(obs)
    slowed = agent.last_solve.ego_trajectory

    def travelled(plan: np.ndarray) -> float:  # plan (N + 1, 3): x, y [m], heading
        return float(np.hypot(*np.diff(plan[:, :2], axis=0).T).sum())

    assert travelled(slowed) < 0.5 * travelled(free)
    agent.speed_limit = math.inf
    assert agent._measure(0, obs).p[1] == scenario.ego.v_ref


@pytest.mark.parametrize("bad", [-1.0, math.nan, -math.inf, True, "fast", None])
def test_a_bad_speed_limit_is_named(bad):
    agent = RMPC(Scenario.preset("low"), max_solve_time=math.inf)
    with pytest.raises((TypeError, ValueError), match="speed_limit"):
        agent.speed_limit = bad
    assert agent.speed_limit == math.inf
