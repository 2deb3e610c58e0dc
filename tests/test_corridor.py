"""The path's corridor: the MPC's planned ego centre keeps within a half width of the arc."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents import RMPC, SMPC
from agents.mpc import fallback
from agents.mpc.nlp.corridor import CORRIDOR_SLACK
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


def test_the_soft_variants_soften_the_corridor_and_without_one_nothing_changes():
    """A soft variant has one corridor slack per stage in two one-sided rows (at a cost above every
    risk slack's); the hard variant one two-sided row; no corridor: no corridor slack at all."""
    scenario = Scenario.preset("medium").replace(corridor=0.4)
    N = scenario.horizon
    agent = RMPC(scenario, max_solve_time=math.inf)
    hard, soft = agent._problem("general"), agent._problem("general_soft")
    assert hard.corridor_rows.size == N and hard.corridor_slack.size == 0
    assert soft.corridor_rows.size == soft.corridor_slack.size == 2 * N
    tags = [soft.w_tags[i] for i in soft.slack_index]
    corridor = [j for j, tag in enumerate(tags) if tag[2] == CORRIDOR_SLACK]
    assert [tags[j][0] for j in corridor] == list(range(1, N + 1))
    assert sorted(set(soft.corridor_slack)) == corridor
    risk = [j for j, tag in enumerate(tags) if tag[2] != CORRIDOR_SLACK]
    assert soft.slack_costs[corridor].min() > 2 * soft.slack_costs[risk].max()
    lower = np.isfinite(soft.lbg[soft.corridor_rows])
    assert lower.sum() == N and np.all(np.isinf(soft.ubg[soft.corridor_rows[lower]]))
    plain = RMPC(Scenario.preset("medium"), max_solve_time=math.inf)._problem("general_soft")
    assert plain.corridor_rows.size == plain.corridor_slack.size == 0
    assert all(plain.w_tags[i][2] != CORRIDOR_SLACK for i in plain.slack_index)


@pytest.mark.parametrize("make", [RMPC, SMPC], ids=["rmpc", "smpc"])
def test_a_box_on_the_lane_gets_a_soft_plan_that_keeps_to_the_lane(make):
    """A parked object 9 m ahead on the path of an ego at 8 m/s: no plan keeps out of its boxes
    (the hard problem is infeasible). The soft plan brakes in its lane, entering the boxes, rather
    than swerving out of the corridor (without one it swerves 10 m off the path)."""
    base = Scenario.preset("low")
    lam = base.path.lambda_start + 20.0
    ahead = point(base.path, lam + 9.0)
    parked = {"object_start": (ahead[0], ahead[1], ahead[2] + math.pi), "object_speed": 0.0}
    scenario = base.replace(ego_start=point(base.path, lam), initial_input=(8.0, 0.0), **parked)
    offsets = {}
    for corridor in (0.5, math.inf):
        sc = scenario.replace(corridor=corridor)
        agent = make(sc, max_solve_time=math.inf)
        agent.predict(scenario_observation(sc))
        report = agent.last_solve
        assert report.fallback == "soft" and report.violation > 0.0
        traj = report.ego_trajectory[1:]
        offsets[corridor] = np.abs(lateral_offset(sc.path, traj[:, 0], traj[:, 1]))
    assert np.all(offsets[0.5] <= 0.5 + 1e-3)
    assert offsets[math.inf].max() > 2.0


def test_the_fallback_ranks_the_corridor_first_then_the_risk():
    """The manoeuvre that spends fewer stages outside the corridor wins, over more clearance and over
    a risk that stays within epsilon longer; among equals the risk decides, then the clearance."""
    risk = np.zeros((2, 4))
    clearance = np.array([[5.0, 5.0, 5.0, 5.0], [1.0, 1.0, 1.0, 1.0]])
    outside = np.array([[False, True, True, True], [False, False, False, False]])
    assert fallback.safest(risk, clearance, 0.0) == 0
    assert fallback.safest(risk, clearance, 0.0, outside) == 1
    risk[1, 1:] = 1.0  # the one in the corridor meets the risk at n = 2: it still wins
    assert fallback.safest(risk, clearance, 0.0, outside) == 1
    assert fallback.safest(risk, clearance, 0.0, np.zeros_like(outside)) == 0  # equals: the risk
    with pytest.raises(ValueError, match="outside"):
        fallback.safest(risk, clearance, 0.0, outside[:, :2])


def test_the_family_follows_a_curved_path_only_with_a_corridor():
    """On a curved lane, the path followers keep the ego near the arc where every straight or
    full-lock member leaves it; without a corridor the family is the twelve of before."""
    from agents.mpc import guesses

    base = Scenario.preset("low").replace(curvature=-0.077, lambda_start=-20.4, v_ref=5.0)
    lam = base.path.lambda_start + 2.0
    start = point(base.path, lam)
    x0 = np.array([*start, lam, 5.0, -0.077 * 5.0])
    assert list(fallback.manoeuvres(base, x0)) == list(fallback.MANOEUVRES)
    scenario = base.replace(corridor=1.0)
    family = fallback.manoeuvres(scenario, x0)
    assert list(family) == [*fallback.MANOEUVRES, *fallback.FOLLOWERS]
    problem = RMPC(scenario, max_solve_time=math.inf)._problem("free")
    worst = {}
    for name, inputs in family.items():
        states = guesses.rollout(problem, x0, inputs)[1:]
        worst[name] = float(np.max(np.abs(lateral_offset(scenario.path, states[:, 0], states[:, 1]))))
    assert worst["hold_path"] <= 1.0 and worst["brake_path"] <= 1.0
    assert min(worst[n] for n in ("hold", "hold_left", "hold_right")) > 1.0


def scenario_observation(scenario: Scenario) -> np.ndarray:
    import gymnasium as gym

    import risk_env  # noqa: F401  (registers the env)

    return gym.make("RiskCrossing-v0", scenario=scenario).reset(seed=0)[0]
