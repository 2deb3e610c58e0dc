"""The path's corridor: the MPC's planned ego centre keeps within a half width of the arc."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents import RMPC
from risk_env.models.path import lateral_offset, point, project
from risk_env.scenario.scenario import Scenario


@settings(max_examples=60, deadline=None)
@given(
    curvature=st.sampled_from([0.0, 0.003, -0.02, 0.08, -0.11]),
    share=st.floats(-1.0, 0.3),
    offset=st.floats(-3.0, 3.0),
)
def test_the_lateral_offset_is_the_signed_distance_to_the_arc(curvature, share, offset):
    """A point ``offset`` to the left of the arc's point at ``lam`` lies ``offset`` from it, and
    projects back onto ``lam`` (on the path and a little beyond its goal)."""
    start = -95.0 if abs(curvature) < 0.02 else -25.0
    path = Scenario().replace(curvature=curvature, lambda_start=start).path
    lam = -share * start
    x, y, theta = point(path, lam)
    px, py = x - offset * math.sin(theta), y + offset * math.cos(theta)
    assert lateral_offset(path, px, py) == pytest.approx(offset, abs=1e-9)
    assert project(path, px, py) == pytest.approx(lam, abs=1e-6)


def test_the_plan_keeps_within_the_corridor_and_none_adds_no_rows():
    base = Scenario.preset("medium")
    scenario = base.replace(corridor=0.3, ego_start=point(base.path, base.path.lambda_start + 20.0))
    agent = RMPC(scenario, max_solve_time=math.inf)
    plain = RMPC(Scenario.preset("medium"), max_solve_time=math.inf)
    obs = scenario_observation(scenario)
    agent.predict(obs)
    report = agent.last_solve
    pr = agent._problem(report.variant)
    assert pr.corridor_rows.size == scenario.horizon
    assert plain._problem(report.variant).corridor_rows.size == 0
    offsets = lateral_offset(scenario.path, report.ego_trajectory[1:, 0], report.ego_trajectory[1:, 1])
    assert np.all(np.abs(offsets) <= 0.3 + 1e-6)


def test_an_ego_that_starts_outside_gets_a_corridor_it_can_keep():
    """Outside the corridor at the start, the step widens it to its offset plus the re-entry
    margin: the start alone never makes the problem infeasible."""
    from agents.mpc.step import CORRIDOR_REENTRY

    base = Scenario.preset("low")
    x, y, theta = point(base.path, base.path.lambda_start + 5.0)
    start = (x - 1.2 * math.sin(theta), y + 1.2 * math.cos(theta), theta)
    scenario = base.replace(corridor=0.5, ego_start=start)
    agent = RMPC(scenario, max_solve_time=math.inf)
    agent.predict(scenario_observation(scenario))
    report = agent.last_solve
    assert report.fallback is None
    offsets = np.abs(
        lateral_offset(scenario.path, report.ego_trajectory[1:, 0], report.ego_trajectory[1:, 1])
    )
    assert np.all(offsets <= 1.2 + CORRIDOR_REENTRY + 1e-6)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, "1"])
def test_a_bad_corridor_is_named(bad):
    with pytest.raises((TypeError, ValueError), match="path.corridor"):
        Scenario().replace(corridor=bad)


def scenario_observation(scenario: Scenario) -> np.ndarray:
    import gymnasium as gym

    import risk_env  # noqa: F401  (registers the env)

    return gym.make("RiskCrossing-v0", scenario=scenario).reset(seed=0)[0]
