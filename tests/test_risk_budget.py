"""The SMPC's episode risk budget and risk weight (agents.mpc.nlp.risk_budget): bad input, the budget row in a
closed loop, the accumulator against the env's episode risk, B = 0 against epsilon = 0."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import risk_env  # noqa: F401
from agents import RMPC, SMPC
from agents.mpc.nlp import risk_budget as rb
from risk_env.scenario.scenario import Scenario


@pytest.mark.parametrize(
    ("value", "error"),
    [
        (-0.1, ValueError),
        (math.nan, ValueError),
        (math.inf, ValueError),
        ("a lot", TypeError),
        (True, TypeError),
    ],
)
@pytest.mark.parametrize("name", ["risk_budget", "risk_weight"])
def test_bad_budget_and_weight_are_named(name: str, value: object, error: type) -> None:
    with pytest.raises(error, match=name):
        SMPC(Scenario.preset("low", severity="probability"), **{name: value})


@pytest.mark.parametrize("name", ["risk_budget", "risk_weight"])
def test_rmpc_rejects_budget_and_weight(name: str) -> None:
    with pytest.raises(ValueError, match=f"{name}=0.05 given to the RMPC"):
        RMPC(Scenario.preset("low"), **{name: 0.05})


def test_unbounded_step_needs_a_budget() -> None:
    with pytest.raises(ValueError, match="needs a risk_budget"):
        SMPC(Scenario.preset("low", severity="probability"), risk_tolerance=math.inf)


def test_effective_tolerance_and_parameters() -> None:
    assert rb.effective_tolerance(0.2, None, 1e-3, 1.0) == 0.2
    assert rb.effective_tolerance(math.inf, 0.05, 1e-3, 1.0) == pytest.approx(0.051)
    assert rb.effective_tolerance(0.01, 0.05, 1e-3, 1.0) == 0.01
    assert rb.effective_tolerance(math.inf, 0.0, 1e-3, 1.0) == 0.0
    # the row (B' - spent - R_N) nu - c_N + off >= backoff, c_N = nu sum_{n<N} R_n, holds iff
    # spent + sum_n R_n <= B - backoff B - RESOLUTION scale, with nu = 1/scale whatever B
    for budget, scale in ((0.05, 1.0), (0.01, 1000.0), (3e4, 1000.0), (2e-7, 0.01)):
        shifted, spent, nu, off, weight = rb.terms_parameters(budget, 0.2 * budget, 2.0, scale, 1e-3)
        assert (spent, nu, off, weight) == (0.2 * budget, 1.0 / scale, 0.0, 2.0)
        edge = budget - 1e-3 * budget - rb.RESOLUTION * scale  # spent + sum_n R_n at the row's bound
        assert (shifted - edge) * nu == pytest.approx(1e-3, rel=1e-9)
    np.testing.assert_allclose(rb.terms_parameters(0.0, 0.0, None), [0.0, 0.0, 0.0, 1.0, 0.0])


def _episode(agent: SMPC, env: gym.Env, seed: int) -> tuple[dict, list[float], list[np.ndarray]]:
    obs, info = env.reset(seed=seed)
    agent.reset()
    applied, actions, done = [], [], False
    while not done:
        action, _ = agent.predict(obs)
        applied.append(float(np.asarray(agent.last_solve.risk_fn())[0]))
        actions.append(action)
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    return info, applied, actions


@pytest.mark.parametrize("allocation", ["share", "horizon"])
def test_budget_holds_in_closed_loop_and_accumulator_is_the_applied_sum(allocation: str) -> None:
    """Medium uncertainty, sampled motion: the episode risk stays within B whenever no fallback
    acted, and the agent's spent risk is the sum of its applied one-step risks and matches the
    env's ``info["episode_risk"]`` (float32 observations: 1e-5 relative). Seed 1 spends most of B."""
    budget = 0.3
    env = gym.make("RiskCrossing-v0", uncertainty="medium", severity="probability", object_motion="sampled")
    agent = SMPC.from_env(
        env,
        risk_budget=budget,
        risk_tolerance=math.inf,
        max_solve_time=math.inf,
        budget_allocation=allocation,
    )
    rows = agent.horizon if allocation == "horizon" else 0  # "share": no rows, a step's epsilon
    assert agent._problem("general").acc_index.size == rows
    spent_any = 0.0
    for seed in (0, 1):
        info, applied, _ = _episode(agent, env, seed)
        assert agent.spent_risk() == pytest.approx(sum(applied), rel=1e-12, abs=1e-15)
        assert agent.spent_risk() == pytest.approx(info["episode_risk"], rel=1e-5, abs=1e-9)
        if agent.failures == 0:
            assert info["episode_risk"] <= budget * (1 + 1e-6)
        spent_any = max(spent_any, info["episode_risk"])
    assert spent_any > 0.5 * budget  # the budget was used, so the row was active


def test_zero_budget_is_zero_tolerance() -> None:
    env = gym.make("RiskCrossing-v0", uncertainty="low", severity="probability", max_steps=15)
    zero_budget = SMPC.from_env(env, risk_budget=0.0, risk_tolerance=math.inf, max_solve_time=math.inf)
    zero_eps = SMPC.from_env(env, risk_tolerance=0.0, max_solve_time=math.inf)
    assert zero_budget._epsilon == 0.0 and zero_budget._risk_variant() == "zero"
    info_b, _, actions_b = _episode(zero_budget, env, 0)
    info_e, _, actions_e = _episode(zero_eps, env, 0)
    np.testing.assert_allclose(np.array(actions_b), np.array(actions_e), atol=1e-4)
    assert info_b["episode_risk"] == info_e["episode_risk"] == 0.0


def test_weight_lowers_the_planned_risk() -> None:
    """A heavy risk weight plans less summed risk than none at the same first step."""
    env = gym.make("RiskCrossing-v0", uncertainty="medium", severity="probability")
    obs, _ = env.reset(seed=0)
    sums = []
    for weight in (None, 1e4):
        agent = SMPC.from_env(env, risk_tolerance=0.05, risk_weight=weight, max_solve_time=math.inf)
        agent.predict(obs)
        sums.append(float(np.sum(agent.last_solve.risk_fn())))
    assert sums[0] > 1e-3
    assert sums[1] < 0.5 * sums[0]


def test_budget_and_weight_sum_over_every_object_slot() -> None:
    """Two objects: one p layout ([epsilon, v_ref, 2 slot blocks, TERMS]); the budget's and the
    weight's per-stage R is the sum over the active slots, so the agent's spent risk is the env's
    summed episode risk, and the budget holds without a fallback."""
    from agents.mpc.nlp.parameters import SLOT_SIZE, TERMS

    budget = 0.3
    # a short horizon: a cheaper NLP, and plans that spend most of B (at the default 6 steps this
    # episode spent none of it)
    env = gym.make(
        "RiskCrossing-v0",
        uncertainty="medium",
        severity="probability",
        scene="two_crossing",
        max_steps=40,
        horizon=3,
    )
    agent = SMPC.from_env(
        env,
        risk_budget=budget,
        risk_weight=1.0,
        risk_tolerance=math.inf,
        max_solve_time=math.inf,
        budget_allocation="horizon",
    )
    assert agent.slots == 2
    pr = agent._problem("general")
    assert pr.evaluate.size_in(1)[0] == 2 + 2 * SLOT_SIZE + TERMS  # exact risk: no risk data
    row_kinds = {pr.g_tags[i][1] for i in pr.risk_rows}
    assert row_kinds == {"risk", "budget"}
    info, applied, _ = _episode(agent, env, 0)
    assert agent.spent_risk() == pytest.approx(sum(applied), rel=1e-12, abs=1e-15)
    assert agent.spent_risk() == pytest.approx(info["episode_risk"], rel=1e-5, abs=1e-9)
    if agent.failures == 0:
        assert info["episode_risk"] <= budget * (1 + 1e-6)
    assert info["episode_risk"] > 0.5 * budget  # the budget was used, so its row was active


def test_a_share_of_what_is_left_per_step() -> None:
    """``budget_allocation="share"``: every step's one-step risk is at most alpha times what was
    left of the budget before it, so the budget never runs out."""
    budget, share = 0.3, 0.5
    env = gym.make("RiskCrossing-v0", uncertainty="medium", severity="probability", object_motion="sampled")
    agent = SMPC.from_env(
        env, risk_budget=budget, budget_share=share, risk_tolerance=math.inf, max_solve_time=math.inf
    )
    obs, _ = env.reset(seed=1)
    agent.reset()
    done, spent, largest = False, 0.0, 0.0
    while not done:
        action, _ = agent.predict(obs)
        report = agent.last_solve
        assert report.risk_tolerance == pytest.approx(share * (budget - spent), rel=1e-12)
        if report.fallback is None:
            assert report.risk[0] <= share * (budget - spent) + 1e-9
        spent += float(report.risk[0])
        largest = max(largest, float(report.risk[0]))
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    assert agent.spent_risk() == pytest.approx(spent, rel=1e-12)
    assert spent < budget and largest > 0.0
    with pytest.raises(ValueError, match=r"budget_share must lie in \(0, 1\]"):
        SMPC.from_env(env, risk_budget=budget, budget_share=0.0)
    with pytest.raises(ValueError, match="budget_allocation must be one of"):
        SMPC.from_env(env, risk_budget=budget, budget_allocation="greedy")
