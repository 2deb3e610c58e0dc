"""The MPC agents: one solve, the RMPC's boxes, SMPC(epsilon = 0) = RMPC, closed loops in the env,
the fallback, the predictor protocol and argument checks.

Closed loops run in ``gym.make("RiskCrossing-v0")``; plans are checked against the env's own numpy
estimators (:func:`risk_env.make_estimator`) on :func:`risk_env.predict_array` beliefs.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import risk_env  # noqa: F401  (registers RiskCrossing-v0)
from agents import RMPC, SMPC, Policy, SolveReport
from agents.mpc import fallback, guesses
from agents.mpc.nlp.budget import Budget, CallTimes
from agents.mpc.nlp.settings import SolverSettings
from risk_env import Scenario, make_estimator, predict_array
from risk_env import observation as ob
from risk_env.risk.estimators import signed_box_distance

UNCAPPED = math.inf
"""``max_solve_time`` of tests about the plans themselves: no wall-time cap, so a busy machine
cannot turn a slow solve into a fallback."""
RISK_TOLERANCE_J = 1.0
"""Slack [J] on the exact risk of a converged plan (solver tolerance 1e-6 on risk/1000 J, plus
the back-off that keeps it 0.1 J inside)."""


def start_observation(scenario: Scenario) -> np.ndarray:
    env = gym.make("RiskCrossing-v0", scenario=scenario)
    obs, _ = env.reset(seed=0)
    return obs


def check_action(scenario: Scenario, action: np.ndarray, last: np.ndarray) -> None:
    ego, dt = scenario.ego, scenario.dt
    assert action.dtype == np.float32 and action.shape == (2,)
    assert np.all(np.isfinite(action))
    v, w = (float(a) for a in action)
    assert ego.v_min - 1e-6 <= v <= ego.v_max + 1e-6
    assert abs(w) <= ego.omega_max + 1e-6
    assert abs(v - last[0]) <= ego.accel_max * dt + 1e-5
    assert abs(w - last[1]) <= ego.omega_rate_max * dt + 1e-5


def plan_risk(agent, scenario: Scenario, obs: np.ndarray, estimator: str) -> np.ndarray:
    """The plan's risk at n = 1..N by the env's estimator, against predict_array's beliefs."""
    report = agent.last_solve
    beliefs = predict_array(scenario, ob.split(obs).object_measurement)[1:]
    ego = np.column_stack([report.ego_trajectory[1:], report.inputs[:, 0]])
    return make_estimator(estimator, scenario).risk(ego, beliefs)


def closed_loop(agent, env: gym.Env, steps: int) -> dict[str, np.ndarray]:
    """Run ``agent`` in ``env`` for up to ``steps`` steps; arrays over the steps taken (the
    reports: a list)."""
    obs, info = env.reset(seed=0)
    agent.reset()
    record: dict[str, list] = {
        "ego": [info["ego"]],
        "distance": [info["distance"]],
        "risk": [],
        "action": [],
        "plan_risk": [],
        "reports": [],
    }
    start = True
    for _ in range(steps):
        action, _ = agent.predict(obs, episode_start=np.array([start]))
        start = False
        check_action(env.unwrapped.scenario, action, ob.split(obs).ego_input)
        obs, _, terminated, truncated, info = env.step(action)
        record["ego"].append(info["ego"])
        record["distance"].append(info["distance"])
        record["risk"].append(info["risk"])
        record["action"].append(action)
        record["plan_risk"].append(agent.last_solve.risk)
        record["reports"].append(agent.last_solve)
        if terminated or truncated:
            break
    return {k: v if k == "reports" else np.array(v) for k, v in record.items()}


# ----------------------------------------------------------------------------- one solve
@pytest.mark.parametrize(
    ("make", "estimator", "epsilon"),
    [
        (lambda sc: RMPC(sc, max_solve_time=UNCAPPED), "worst_case", 0.0),
        (lambda sc: SMPC(sc, max_solve_time=UNCAPPED), "exact", 0.0),
        (lambda sc: SMPC(sc, max_solve_time=UNCAPPED), "exact", 500.0),
        (lambda sc: SMPC(sc, solver="ipopt", max_solve_time=UNCAPPED), "exact", 1000.0),
        (lambda sc: RMPC(sc, stage_cost="paper", solver="ipopt", max_solve_time=UNCAPPED), "worst_case", 0.0),
    ],
    ids=["rmpc", "smpc-exact-0", "smpc-exact-500", "smpc-exact-1000-ipopt", "rmpc-paper-cost-ipopt"],
)
def test_one_solve_from_the_paper_start(make, estimator: str, epsilon: float) -> None:
    scenario = Scenario.preset("medium", risk_tolerance=epsilon)
    agent = make(scenario)
    obs = start_observation(scenario)
    action, state = agent.predict(obs)
    report = agent.last_solve
    assert state is None
    assert report.success and report.fallback is None and agent.failures == 0
    check_action(scenario, action, np.zeros(2))
    np.testing.assert_allclose(report.action, action)
    np.testing.assert_allclose(report.inputs[0], action, atol=1e-5)
    N = scenario.horizon
    assert report.ego_trajectory.shape == (N + 1, 3) and report.inputs.shape == (N, 2)
    assert report.risk.shape == (N,) and report.lambdas.shape == (N + 1,)
    assert report.lambdas[0] == pytest.approx(float(obs[ob.PROGRESS]))
    risk = plan_risk(agent, scenario, obs, estimator)
    assert np.all(risk <= epsilon + RISK_TOLERANCE_J), risk
    np.testing.assert_allclose(report.risk, risk, rtol=1e-9, atol=1e-9)  # same estimator, same plan


def test_monte_carlo_plan_respects_its_own_draws() -> None:
    """The plan's Monte Carlo risk on the solve's draws (hard indicator) stays within epsilon, up to
    the smoothed form's stated bound (draws near the disc edge, the rounded severity)."""
    scenario = Scenario.preset("medium", risk_tolerance=1000.0)
    # the pilot's 40 draws (they only start the solve): the solvers of the pilot's test below
    agent = SMPC(scenario, risk="monte_carlo", samples=200, pilot_samples=40, seed=3, max_solve_time=UNCAPPED)
    obs = start_observation(scenario)
    agent.predict(obs)
    report = agent.last_solve
    assert report.success
    per_draw = 0.5 * 1000.0 * 5.0**2 / 200  # one draw's largest contribution at |v| <= 5 m/s [J]
    assert np.all(report.risk <= 1000.0 + 2 * per_draw), report.risk
    beliefs = predict_array(scenario, ob.split(obs).object_measurement)[1:]
    ego = np.column_stack([report.ego_trajectory[1:], report.inputs[:, 0]])
    draws = report.risk_fn.args[2]  # (N, J, 3): the draws this solve used
    for n in range(scenario.horizon):
        bound = agent.estimator.smoothing_bound(ego[n], beliefs[n], draws[n])
        assert report.risk[n] <= 1000.0 + float(bound) + 1e-6


# ----------------------------------------------------------------------------- RMPC boxes
def test_rmpc_plan_keeps_the_ego_disc_off_every_truncation_box() -> None:
    scenario = Scenario.preset("high")
    env = gym.make("RiskCrossing-v0", scenario=scenario, risk_estimator="worst_case")
    agent = RMPC.from_env(env, max_solve_time=UNCAPPED)
    obs, _ = env.reset(seed=0)
    r = scenario.collision_distance
    for _ in range(6):
        action, _ = agent.predict(obs)
        report = agent.last_solve
        assert report.success
        beliefs = predict_array(scenario, ob.split(obs).object_measurement)[1:]
        xy = report.ego_trajectory[1:, :2]
        d = signed_box_distance(xy[:, 0] - beliefs.x, xy[:, 1] - beliefs.y, beliefs.half_x, beliefs.half_y)
        assert np.all(d >= r - 1e-3), d
        assert np.all(report.risk == 0.0)
        obs, _, terminated, _, info = env.step(action)
        assert info["risk"] == 0.0
        assert not terminated


# ----------------------------------------------------------------------------- closed loops
def test_exact_smpc_at_zero_tolerance_drives_like_the_rmpc() -> None:
    """SPEC: P = 0 means outside the box, so SMPC(exact, epsilon = 0) is the RMPC."""
    env = gym.make("RiskCrossing-v0", uncertainty="medium", risk_tolerance=0.0)
    smpc = closed_loop(SMPC.from_env(env, max_solve_time=UNCAPPED), env, 15)
    rmpc = closed_loop(RMPC.from_env(env, max_solve_time=UNCAPPED), env, 15)
    assert len(smpc["ego"]) == len(rmpc["ego"]) == 16
    np.testing.assert_allclose(smpc["ego"], rmpc["ego"], atol=1e-3)
    # ... and it differs from an SMPC that tolerates risk
    loose = closed_loop(SMPC.from_env(env, risk_tolerance=1000.0, max_solve_time=UNCAPPED), env, 15)
    assert np.max(np.abs(loose["ego"] - rmpc["ego"])) > 0.5


@pytest.mark.parametrize("make", [RMPC.from_env, SMPC.from_env], ids=["rmpc", "smpc-exact"])
def test_short_closed_loop_low_uncertainty_no_collision(make) -> None:
    env = gym.make("RiskCrossing-v0", uncertainty="low", risk_tolerance=0.0)
    agent = make(env, max_solve_time=UNCAPPED)
    run = closed_loop(agent, env, 30)  # the object has passed the path by then
    assert len(run["action"]) == 30
    assert agent.failures == 0
    assert run["distance"].min() > env.unwrapped.scenario.collision_distance
    assert np.all(run["risk"] == 0.0)  # the env's exact risk at epsilon = 0
    assert run["ego"][-1, 0] > 0.0  # on its way to the goal


def test_smpc_keeps_the_envs_risk_within_tolerance() -> None:
    """With the deterministic object, the env's R_{k+1|k} is the plan's first-step risk."""
    epsilon = 500.0
    env = gym.make("RiskCrossing-v0", uncertainty="medium", risk_tolerance=epsilon)
    agent = SMPC.from_env(env, max_solve_time=UNCAPPED)
    run = closed_loop(agent, env, 20)
    assert agent.failures == 0
    assert np.all(run["risk"] <= epsilon + RISK_TOLERANCE_J), run["risk"]
    assert np.all(run["plan_risk"] <= epsilon + RISK_TOLERANCE_J)
    assert run["plan_risk"].max() > 0.5 * epsilon  # the tolerance is used by the plans


# ----------------------------------------------------------------------------- degradation
def box_clearance(scenario: Scenario, obs: np.ndarray, ego_trajectory: np.ndarray) -> np.ndarray:
    """Worst-case clearance [m] of a plan's states n = 1..N: distance to the truncation box - 3 m."""
    beliefs = predict_array(scenario, ob.split(obs).object_measurement)[1:]
    x, y = ego_trajectory[1:, 0], ego_trajectory[1:, 1]
    distance = signed_box_distance(x - beliefs.x, y - beliefs.y, beliefs.half_x, beliefs.half_y)
    return distance - scenario.collision_distance


def fail_variants(agent, monkeypatch, failing: tuple[str, ...]) -> list[str]:
    """Make every solver call of the ``failing`` variants fail; returns the variants called."""
    calls: list[str] = []
    original = agent._call

    def call(pr, args, rung=0):
        calls.append(pr.variant)
        if pr.variant in failing:
            return {}, "forced failure", False, 0, {}
        return original(pr, args, rung)

    monkeypatch.setattr(agent, "_call", call)
    return calls


def inside_the_box(scenario: Scenario) -> np.ndarray:
    obs = start_observation(scenario).copy()
    obs[ob.EGO_POSE] = (5.0, -3.5, np.pi / 2)  # on top of the object, moving with it
    obs[ob.EGO_INPUT] = (2.0, 0.1)
    return obs


@pytest.mark.parametrize(
    ("make", "epsilon"),
    [
        (lambda sc: RMPC(sc, max_solve_time=UNCAPPED), 0.0),
        (lambda sc: SMPC(sc, max_solve_time=UNCAPPED), 0.0),
        (lambda sc: SMPC(sc, max_solve_time=UNCAPPED), 1000.0),
    ],
    ids=["rmpc", "smpc-exact-0", "smpc-exact-1000"],
)
def test_soft_problem_is_an_exact_penalty_where_the_hard_one_is_feasible(make, epsilon) -> None:
    """Along a closed loop, the soft problem solved from the same point as the hard one returns
    the hard plan with zero slacks: rho exceeds the risk rows' multipliers."""
    from agents.mpc.nlp.ocp import soft_variant
    from agents.mpc.step import Step

    env = gym.make("RiskCrossing-v0", uncertainty="medium", risk_tolerance=epsilon, max_steps=14)
    agent = make(env.unwrapped.scenario)
    obs, _ = env.reset(seed=0)
    agent.reset()
    binding = 0
    for _ in range(14):
        action, _ = agent.predict(obs)
        report = agent.last_solve
        assert report.fallback is None and agent.failures == 0
        if report.variant != "free":
            # the soft problem, started at the hard plan (slack costs 0), stays there
            step = Step(agent._context(), agent._measure(1, obs), Budget(math.inf))
            hard, soft = agent._problem(step.variant), agent._problem(soft_variant(step.variant))
            plan = np.column_stack([report.inputs, report.path_speed])
            w0 = guesses.pack(soft, guesses.rollout(soft, step.x0, plan), plan)
            w0[soft.slack_index] = 1e-6
            out, _ = step.solve(soft, [(w0, None, None)], reserve=0.0)
            assert out is not None
            slacks = out["x"][soft.slack_index]
            assert np.all(np.abs(slacks) <= 1e-6), slacks
            # to the solver's tolerance (tol = 1e-4, scaled by the multipliers rho_n of the slacks'
            # bounds), on a problem flat in some inputs: both solves stop at tol, so the first
            # input may differ along a flat direction (up to 0.11 m/s at one step) while the
            # objectives agree (below)
            np.testing.assert_allclose(out["x"][soft.u_index][0, :2], report.inputs[0], atol=0.15)
            w = np.zeros(hard.n_w)  # the soft plan in the hard problem's layout: its objective
            w[hard.x_index], w[hard.u_index] = out["x"][soft.x_index], out["x"][soft.u_index]
            assert float(hard.evaluate(w, step.p)[0]) == pytest.approx(report.cost, rel=1e-3)
            # ... because rho exceeds the hard rows' multipliers
            hard_out = agent._memory[0]
            multipliers = (
                np.abs(hard_out["lam_g"][hard.risk_rows]) if hard_out["variant"] == hard.variant else 0.0
            )
            binding += bool(np.any(multipliers > 1e-3))
            assert np.all(multipliers < soft.slack_costs)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    assert binding >= 3  # the check saw active risk rows


def test_a_feasible_hard_problem_whose_calls_fail_is_solved_through_its_exact_penalty(monkeypatch) -> None:
    """The hard problem is feasible but its calls fail: the soft plan has zero slacks, so it is the
    hard problem's solution (the penalty is exact): level (a), never "soft"."""
    scenario = Scenario.preset("medium", risk_tolerance=0.0)
    agent = SMPC(scenario, max_solve_time=math.inf)  # the degradation's logic, not the time cap
    obs = start_observation(scenario)
    reference = SMPC(scenario, max_solve_time=UNCAPPED)
    reference.predict(obs)
    calls = fail_variants(agent, monkeypatch, ("zero",))
    agent.predict(obs)
    report = agent.last_solve
    assert "zero_soft" in calls and report.fallback is None and agent.failures == 0
    assert report.retried and report.variant == "zero_soft" and report.violation == 0.0
    assert report.failed_calls == calls.count("zero") == 3
    # a plan of the hard problem (from another start than the reference's: maybe another optimum)
    assert np.all(report.risk == 0.0) and report.cost == pytest.approx(reference.last_solve.cost, rel=0.05)
    assert np.all(box_clearance(scenario, obs, report.ego_trajectory) >= -1e-6)


def test_soft_plan_inside_the_box_reports_its_violation_and_escapes() -> None:
    scenario = Scenario.preset("low")
    agent = RMPC(scenario, max_solve_time=UNCAPPED)
    obs = inside_the_box(scenario)
    for count in (1, 2):
        action, _ = agent.predict(obs)
        report = agent.last_solve
        assert report.fallback == "soft" and report.success and report.variant == "general_soft"
        assert report.violation > 0.1 and agent.failures == count
        check_action(scenario, action, obs[ob.EGO_INPUT])
        assert np.all(np.isfinite(report.ego_trajectory)) and np.all(np.isfinite(report.risk))
    # the soft plan leaves the boxes faster than braking does
    clearance = box_clearance(scenario, obs, report.ego_trajectory)
    x0 = np.array([5.0, -3.5, np.pi / 2, 0.0, 2.0, 0.1])
    base = agent._problem("free")
    braking = guesses.rollout(base, x0, fallback.manoeuvres(scenario, x0)["brake"])
    assert clearance.sum() > box_clearance(scenario, obs, braking).sum()
    agent.reset()
    assert agent.failures == 0 and agent.last_solve is None


def test_safest_manoeuvre_when_every_solve_fails(monkeypatch) -> None:
    """Every call fails: the agent applies the manoeuvre that keeps the worst-case clearance
    largest, within the rate limits, and never brakes into the object's path."""
    scenario = Scenario.preset("medium")
    agent = RMPC(scenario, max_solve_time=UNCAPPED)
    fail_variants(agent, monkeypatch, ("free", "general", "general_soft"))
    obs = start_observation(scenario).copy()
    obs[ob.EGO_POSE] = (0.0, -2.0, 0.0)  # heading across the object's path, 5 m to its left
    obs[ob.EGO_INPUT] = (4.0, 0.0)
    action, _ = agent.predict(obs)
    report = agent.last_solve
    assert report.fallback == "manoeuvre" and not report.success and report.manoeuvre in fallback.MANOEUVRES
    assert report.status.startswith("manoeuvre") and report.failed_calls >= 2
    check_action(scenario, action, obs[ob.EGO_INPUT])
    x0 = np.array([0.0, -2.0, 0.0, 0.0, 4.0, 0.0])
    base = agent._problem("free")
    family = fallback.manoeuvres(scenario, x0)
    clear = {n: box_clearance(scenario, obs, guesses.rollout(base, x0, u)) for n, u in family.items()}
    first = {n: int(np.argmax(c < 0)) if np.any(c < 0) else len(c) for n, c in clear.items()}
    chosen = box_clearance(scenario, obs, report.ego_trajectory)
    assert report.manoeuvre != "brake" and first[report.manoeuvre] == max(first.values())
    assert first[report.manoeuvre] > first["brake"] or chosen.min() > clear["brake"].min()


def test_safest_ranks_time_to_violation_then_clearance() -> None:
    risk = np.array([[0.0, 5.0, 5.0], [0.0, 0.0, 5.0], [0.0, 0.0, 9.0], [5.0, 0.0, 0.0]])
    clearance = np.array([[9.0, 9.0, 9.0], [-1.0, -2.0, -3.0], [1.0, 0.5, -1.0], [9.0, 9.0, 9.0]])
    assert fallback.safest(risk, clearance, epsilon=1.0) == 2  # violates last, and by less
    assert fallback.safest(risk[[0, 3]], clearance[[0, 3]], epsilon=1.0) == 0
    # all violate at n = 1: the least violation there wins, however the later steps look
    assert fallback.safest(np.ones((2, 3)), np.array([[-0.5, -9.0, -9.0], [-1.0, 5.0, 5.0]]), 0.0) == 0
    # none violates: the largest smallest clearance
    assert fallback.safest(np.zeros((2, 3)), clearance[[1, 2]], epsilon=0.0) == 1
    with pytest.raises(ValueError, match="risk and clearance"):
        fallback.safest(np.zeros((2, 3)), np.zeros((3, 3)), epsilon=0.0)


def test_manoeuvres_keep_the_rate_limits() -> None:
    scenario = Scenario.preset("low")
    x0 = np.array([0.0, 0.0, 0.0, -70.0, 2.0, -0.3])
    family = fallback.manoeuvres(scenario, x0)
    assert tuple(family) == fallback.MANOEUVRES and len(family) == 12
    ego, dt = scenario.ego, scenario.dt
    for inputs in family.values():
        v = np.concatenate([[x0[4]], inputs[:, 0]])
        w = np.concatenate([[x0[5]], inputs[:, 1]])
        assert np.all(np.abs(np.diff(v)) <= ego.accel_max * dt + 1e-12)
        assert np.all(np.abs(np.diff(w)) <= ego.omega_rate_max * dt + 1e-12)
        assert np.all((v >= ego.v_min) & (v <= ego.v_max)) and np.all(np.abs(w) <= ego.omega_max)
    assert family["accelerate_left"][-1, 0] == ego.v_max and family["accelerate_left"][-1, 1] == ego.omega_max
    assert family["reverse"][-1, 0] == ego.v_min and family["hold"][0, 0] == x0[4]


def test_too_few_iterations_end_in_a_manoeuvre() -> None:
    scenario = Scenario.preset("medium", risk_tolerance=500.0)
    agent = SMPC(scenario, max_iter=1, max_solve_time=UNCAPPED)
    action, _ = agent.predict(start_observation(scenario))
    assert agent.last_solve.fallback == "manoeuvre" and agent.failures == 1
    check_action(scenario, action, np.zeros(2))


def test_the_time_cap_holds_and_hands_over_to_the_next_level() -> None:
    scenario = Scenario.preset("medium", risk_tolerance=1000.0)
    obs = start_observation(scenario)
    tiny = SMPC(scenario, max_solve_time=1e-4)  # no solver call fits
    action, _ = tiny.predict(obs)
    report = tiny.last_solve
    assert report.fallback == "manoeuvre" and report.capped and report.iterations == 0
    check_action(scenario, action, np.zeros(2))
    env = gym.make("RiskCrossing-v0", scenario=scenario.replace(max_steps=12))
    agent = SMPC.from_env(env)  # the default cap, 20 % of the step (its solvers are the rung test's)
    assert agent.max_solve_time == pytest.approx(0.1)
    run = closed_loop(agent, env, 12)
    assert len(run["action"]) >= 6
    # the step's own work (CPU time: wall time also counts whatever else the machine ran), to the
    # cap's own slack: the prediction of a call's time and what follows the last call
    assert max(r.cpu_time for r in run["reports"]) <= agent.max_solve_time + 0.02


def test_rungs_hold_the_solvers_own_limits() -> None:
    fatrop = SolverSettings(max_iter=100, rungs=3, time_limit=0.1)
    assert fatrop.rung_limits() == ((100, None), (50, None), (25, None))
    assert fatrop.plugin_options(2)["fatrop"]["max_iter"] == 25
    ipopt = SolverSettings(solver="ipopt", max_iter=100, rungs=3, time_limit=0.1)
    assert ipopt.rung_limits() == ((100, 0.1), (100, 0.05), (100, 0.025))
    assert ipopt.plugin_options(1)["ipopt"]["max_wall_time"] == 0.05
    times = CallTimes(fatrop.rung_limits(), prior=1e-3, failing=4e-3)
    # before any call: 1.3 x the priors per iteration, for a long one the failing call's, doubled
    # until a long call was measured (the probe may price a failing call's iterations low)
    assert times.per_iteration(5) == pytest.approx(1.3e-3) and times.per_iteration(25) == pytest.approx(
        1.04e-2
    )
    assert times.rung(0.6) == 1 and times.rung(0.3) == 2 and times.rung(0.2) is None
    assert times.per_iteration(5) == pytest.approx(0.8 * 1.3e-3)  # discounted after the skip
    for _ in range(10):  # a step's later calls that found no time left: not evidence of pessimism
        assert times.rung(1e-4) is None
    # the discount stops at the measured time itself: a 135 ms call was once predicted at 61 ms
    assert times.per_iteration(5) == pytest.approx(1e-3) and times.per_iteration(25) == pytest.approx(8e-3)
    times.record(30, 30 * 1e-3 + 5e-4)  # a long call at 1 ms per iteration: long calls are measured
    assert times.per_iteration(25) == pytest.approx(4e-3 * 1.3)  # the failing prior, not doubled
    for _ in range(20):
        times.record(30, 30 * 1e-3 + 5e-4)
    assert times.per_iteration(25) == pytest.approx(1.3e-3) and times.rung(0.2) == 0
    with pytest.raises(ValueError, match="rungs"):
        SolverSettings(rungs=0)


@pytest.mark.parametrize("make", [RMPC, SMPC], ids=["rmpc", "smpc-exact"])
def test_every_rung_keeps_its_iteration_limit_after_the_build(make) -> None:
    """CasADi 3.8's fatrop runs every call with its defaults once a solver was called with another
    split of the bounds into equalities and inequalities: the build's timing calls must use the
    steps' pattern (they once left the soft problems' slacks unbounded, so the smallest soft rung
    ran hundreds of iterations at a limit of 4)."""
    from agents.mpc.nlp.ocp import soft_variant
    from agents.mpc.step import Step

    env = gym.make("RiskCrossing-v0", uncertainty="high", max_steps=5)
    agent = make.from_env(env, max_solve_time=0.1)
    obs, _ = env.reset(seed=0)
    agent.predict(obs)
    step = Step(agent._context(), agent._measure(0, obs), Budget(math.inf))
    for variant in (step.variant, soft_variant(step.variant)):
        pr = agent._problem(variant)
        args = step.args(pr)
        for rung, solver in enumerate(pr.solvers):
            solver(**args, x0=np.zeros(pr.n_w))  # a poor start: every rung runs to its limit
            assert int(solver.stats()["iter_count"]) <= pr.limits[rung][0] + 1, (variant, rung)


def test_calls_past_their_iteration_limit_are_counted() -> None:
    """fatrop may run past max_iter (agents/mpc/nlp/budget.py): such calls are tallied, the others not."""
    from types import SimpleNamespace

    from agents.mpc import attempts

    limits = SolverSettings(max_iter=8, rungs=2, time_limit=1.0).rung_limits()
    problem = SimpleNamespace(limits=limits, times=CallTimes(limits, prior=1e-4, failing=1e-4))
    runs = iter([(4, False), (9, False), (31, True)])  # 9 = the limit 8 plus fatrop's count of one more

    def call(pr, args, rung):
        iterations, ok = next(runs)
        return {"f": np.zeros(1)}, "status", ok, iterations, {}

    tally = attempts.Tally()
    guesses = [(np.zeros(2), None, None)] * 3
    out, calls = attempts.solve(call, problem, guesses, {}, Budget(1.0), 0.0, tally)
    assert out is not None and calls == 3
    assert tally.failed_calls == 2 and tally.overran_calls == 1 and tally.iterations == 44


# ----------------------------------------------------------------------------- API
def test_predictor_protocol_batches_and_episode_start() -> None:
    env = gym.make("RiskCrossing-v0", uncertainty="low")
    agent = RMPC.from_env(env, risk_tolerance=100.0, max_solve_time=UNCAPPED)
    assert isinstance(agent, Policy)
    assert agent.risk_tolerance == 100.0 and env.unwrapped.scenario.risk_tolerance == 0.0
    obs, _ = env.reset(seed=0)
    single, _ = agent.predict(obs, episode_start=True)
    batch = np.stack([obs, obs, obs])
    actions, state = agent.predict(batch, episode_start=np.ones(3, dtype=bool))
    assert state is None and actions.shape == (3, 2) and actions.dtype == np.float32
    np.testing.assert_allclose(actions, np.broadcast_to(single, (3, 2)), atol=1e-5)
    assert len(agent.last_solves) == 3 and isinstance(agent.last_solve, SolveReport)
    # a second step warm-starts; an episode start cold-starts and gives the first action again
    obs2, *_ = env.step(single)
    agent.predict(obs2)
    again, _ = agent.predict(obs, episode_start=np.array([True]))
    np.testing.assert_allclose(again, single, atol=1e-4)
    with pytest.raises(ValueError, match="shape"):
        agent.predict(np.zeros(14))


def test_monte_carlo_draws_are_reproducible() -> None:
    scenario = Scenario.preset("medium", risk_tolerance=1000.0)
    obs = start_observation(scenario)
    a = SMPC(scenario, risk="monte_carlo", samples=50, seed=7, max_solve_time=UNCAPPED)
    b = SMPC(scenario, risk="monte_carlo", samples=50, seed=7, max_solve_time=UNCAPPED)
    first = a.predict(obs)[0], a.last_solve.risk.copy()
    second = b.predict(obs)[0], b.last_solve.risk.copy()
    np.testing.assert_array_equal(first[0], second[0])
    np.testing.assert_array_equal(first[1], second[1])
    a.reset()
    np.testing.assert_array_equal(a.predict(obs)[0], first[0])
    assert a.samples == 50


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda sc: RMPC(sc, risk_tolerance=-1.0), "-1.0"),
        (lambda sc: SMPC(sc, risk_tolerance=float("nan")), "nan"),
        (lambda sc: RMPC(sc, risk="exact"), "'exact'"),
        (lambda sc: SMPC(sc, risk="worst_case"), "'worst_case'"),
        (lambda sc: SMPC(sc, risk="monte_carlo", samples=0), "samples.*0"),
        (lambda sc: SMPC(sc, risk="monte_carlo", samples=-3), "samples.*-3"),
        (lambda sc: SMPC(sc, risk="monte_carlo", pilot_samples=0.5), "pilot_samples must be an integer"),
        (lambda sc: RMPC(sc, solver="snopt"), "'snopt'"),
        (lambda sc: SMPC(sc, stage_cost="terminal"), "'terminal'"),
        (lambda sc: RMPC(sc, max_iter=0), "max_iter"),
        (lambda sc: RMPC(sc, cold_starts=0), "cold_starts"),
    ],
)
def test_bad_arguments_raise(make, match: str) -> None:
    with pytest.raises((TypeError, ValueError), match=match):  # TypeError: not a number of the type
        make(Scenario.preset("low"))


def test_from_env_needs_a_scenario() -> None:
    with pytest.raises(TypeError, match="scenario"):
        RMPC.from_env(object())


def test_free_variant_when_no_box_is_reachable(monkeypatch) -> None:
    """Far from the object no risk row can bind: the risk-free NLP runs and gives the same plan."""
    scenario = Scenario.preset("low", object_start=(60.0, -80.0, np.pi / 2), risk_tolerance=500.0)
    obs = start_observation(scenario)
    free = SMPC(scenario, max_solve_time=UNCAPPED)
    action, _ = free.predict(obs)
    assert free.last_solve.variant == "free" and free.last_solve.success
    forced = SMPC(scenario, max_solve_time=UNCAPPED)
    monkeypatch.setattr(forced, "_risk_possible", lambda x0, future, slot=0: True)
    forced_action, _ = forced.predict(obs)
    assert forced.last_solve.variant == "general" and forced.last_solve.success
    np.testing.assert_allclose(action, forced_action, atol=1e-3)
    np.testing.assert_allclose(free.last_solve.ego_trajectory, forced.last_solve.ego_trajectory, atol=1e-2)


def test_jit_falls_back_without_a_compiler(monkeypatch) -> None:
    monkeypatch.setenv("CC", "/nonexistent/cc")
    with pytest.warns(UserWarning, match="no C compiler"):
        agent = RMPC(Scenario.preset("low", horizon=3), jit=True, jit_cache=None, max_solve_time=UNCAPPED)
    assert not agent.compiled
    agent.predict(start_observation(agent.scenario))
    assert agent.last_solve.success


def test_compiled_solver_writes_nothing_to_the_working_directory(tmp_path, monkeypatch):
    """The compiled (jit) build: its C source and library go to a private temporary directory and
    the cache, never to the working directory, and it never changes directory (not thread-safe)."""
    work, cache = tmp_path / "work", tmp_path / "cache"
    work.mkdir()
    monkeypatch.chdir(work)

    def no_chdir(path):
        raise AssertionError(f"os.chdir({path!r}) during a build")

    monkeypatch.setattr("os.chdir", no_chdir)
    scenario = Scenario.preset("low", horizon=1)  # the least C code to compile
    agent = RMPC(scenario, jit=True, jit_opt=0, jit_cache=cache, max_solve_time=UNCAPPED)
    assert agent.compiled
    assert list(work.iterdir()) == []
    libraries = sorted(p.name for p in cache.iterdir())
    # free, general and general_soft: every rung of a variant loads its one library
    assert len(libraries) == 3 and all(n.startswith("riskmpc_") and n.endswith(".so") for n in libraries)
    obs = start_observation(scenario)
    action, _ = agent.predict(obs)
    plain = RMPC(scenario, max_solve_time=UNCAPPED)
    np.testing.assert_allclose(action, plain.predict(obs)[0], atol=1e-6)
    assert agent.last_solve.iterations == plain.last_solve.iterations
    # a new process (here: the in-process solver cache emptied) loads the libraries, compiles nothing
    from agents.mpc.nlp import compiled
    from agents.mpc.nlp import solver as mpc

    monkeypatch.setattr(mpc, "_SOLVER_CACHE", type(mpc._SOLVER_CACHE)())
    monkeypatch.setattr(compiled.subprocess, "run", lambda *a, **k: pytest.fail("compiled again"))
    again = RMPC(scenario, jit=True, jit_opt=0, jit_cache=cache, max_solve_time=UNCAPPED)
    assert again.compiled and sorted(p.name for p in cache.iterdir()) == libraries
    np.testing.assert_allclose(again.predict(obs)[0], action, atol=1e-9)
    assert list(work.iterdir()) == []


def test_compiled_solver_falls_back_when_the_compiler_fails(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("CC", "false")  # found on PATH, fails every compilation
    with pytest.warns(UserWarning, match="compiling the solver failed"):
        agent = RMPC(
            Scenario.preset("low", horizon=2), jit=True, jit_cache=tmp_path / "cache", max_solve_time=UNCAPPED
        )
    assert not agent.compiled
    agent.predict(start_observation(agent.scenario))
    assert agent.last_solve.success
    assert [p.name for p in tmp_path.iterdir()] in ([], ["cache"])
    assert not any((tmp_path / "cache").glob("*")) if (tmp_path / "cache").exists() else True


def test_monte_carlo_cold_start_goes_through_the_pilot():
    """An episode's first Monte Carlo step: the pilot (fewer draws) solves from every rollout, the
    full problem once from the pilot's plan."""
    scenario = Scenario.preset("medium", risk_tolerance=1000.0)
    obs = start_observation(scenario)
    agent = SMPC(scenario, risk="monte_carlo", samples=200, pilot_samples=40, seed=3, max_solve_time=UNCAPPED)
    calls = []
    original = agent._call
    monkeypatch_call = lambda pr, args, rung=0: calls.append(pr.variant) or original(pr, args, rung)  # noqa: E731
    agent._call = monkeypatch_call
    agent.predict(obs)
    assert agent.last_solve.success and len(calls) == 1
    assert agent._pilot is not None and agent._pilot.estimator.samples == 40
    assert agent.last_solve.iterations > agent._pilot.last_solve.iterations > 0
    first = agent.last_solve.action.copy()
    agent.reset()  # the pilot's draws restart too: the same first step again
    np.testing.assert_array_equal(agent.predict(obs)[0], first)
    direct = SMPC(
        scenario, risk="monte_carlo", samples=200, pilot_samples=None, seed=3, max_solve_time=UNCAPPED
    )
    direct.predict(obs)
    assert direct.last_solve.success and direct._pilot is None
    np.testing.assert_allclose(agent.last_solve.inputs, direct.last_solve.inputs, atol=0.05)


def test_uncertainty_levels_and_tolerances_share_one_solver(monkeypatch):
    """Epsilon and the uncertainty are solver parameters: one build serves them all, and each agent
    still plans against its own beliefs (a 3-step horizon: the builds this test makes are cheap)."""
    from agents.mpc.nlp import solver as mpc

    # an empty cache of its own (the process's, kept for the tests after this one, comes back after)
    monkeypatch.setattr(mpc, "_SOLVER_CACHE", type(mpc._SOLVER_CACHE)())
    first = SMPC(Scenario.preset("low", risk_tolerance=500.0, horizon=3), max_solve_time=UNCAPPED)
    assert first.build_time > 0
    levels = ("medium", "high")
    others = [
        SMPC(Scenario.preset(level, risk_tolerance=eps, horizon=3), max_solve_time=UNCAPPED)
        for level in levels
        for eps in (250.0, 1000.0)
    ]
    assert all(agent.build_time == 0.0 for agent in others)
    zero = SMPC(Scenario.preset("low", risk_tolerance=0.0, horizon=3), max_solve_time=UNCAPPED)
    assert zero.build_time > 0  # the epsilon = 0 form
    high_zero = SMPC(Scenario.preset("high", risk_tolerance=0.0, horizon=3), max_solve_time=UNCAPPED)
    assert high_zero.build_time == 0.0
    for agent in (first, others[1], others[3]):  # low 500, medium 1000, high 1000
        obs = start_observation(agent.scenario)
        agent.predict(obs)
        risk = plan_risk(agent, agent.scenario, obs, "exact")
        assert agent.last_solve.success and np.all(risk <= agent.risk_tolerance + RISK_TOLERANCE_J)
        np.testing.assert_allclose(agent.last_solve.risk, risk, rtol=1e-9, atol=1e-9)


def test_agents_with_other_starts_and_reference_speeds_share_one_solver():
    """v_ref is a parameter and the starts and the object's inputs are measured: one build serves
    them all, and each agent plans toward its own reference speed."""
    base = Scenario.preset("low", max_steps=30, object_start=(60.0, -80.0, np.pi / 2))
    first = RMPC(base.replace(v_ref=2.0), max_solve_time=UNCAPPED)
    other = RMPC(
        base.replace(
            v_ref=7.0,
            ego_start=(-20.0, 14.0, -0.2),
            initial_input=(1.0, 0.0),
            object_start=(55.0, -75.0, 1.0),
            object_speed=2.0,
        ),
        max_solve_time=UNCAPPED,
    )
    assert other.build_time == 0.0  # the first one's solvers
    for agent in (first, other):
        env = gym.make("RiskCrossing-v0", scenario=agent.scenario)
        run = closed_loop(agent, env, 25)
        assert run["ego"][-1, 3] == pytest.approx(agent.scenario.ego.v_ref, abs=0.05)


def test_agents_with_different_estimators_share_a_process():
    """Solver caching must not hand one estimator's problem (and parameter layout) to another."""
    import gymnasium as gym

    from agents import SMPC
    from benchmarks.rollout import rollout

    env = gym.make("RiskCrossing-v0", uncertainty="low", risk_tolerance=0.0, max_steps=15)
    for risk in ("exact", "monte_carlo"):
        # 50 draws: the solvers of test_monte_carlo_draws_are_reproducible
        agent = SMPC.from_env(env, risk=risk, samples=50, max_solve_time=UNCAPPED)
        record = rollout(agent, env, seed=0)
        assert record.steps == 15 and np.all(np.isfinite(record.actions))


def test_episode_start_of_the_wrong_size_raises():
    from agents import RMPC

    agent = RMPC(Scenario.preset("low"))
    obs = np.zeros((2, ob.SIZE), dtype=np.float32)
    with pytest.raises(ValueError, match="episode_start must have 1 or 2 entries"):
        agent.predict(obs, episode_start=np.array([True, False, True]))


def test_exact_smpc_risk_rows_and_their_jacobian_are_the_estimators() -> None:
    """The exact SMPC's risk row as the solver sees it, at the ego states of plans that use the
    tolerance: its value is ``max(clearance, (epsilon - R) / scale)`` with the env's numpy R,
    conservative by at most the solver rule's shortfall (:class:`risk_env.risk.estimators.ExactRisk`), and
    its Jacobian in the ego's position and speed that value's central differences, to the rule's
    accuracy (the solver differentiates the integral, the differences the rule's nodes too; see
    :func:`risk_env.risk.estimators.disc_probability`): within 2 % each, 0.1 % in the median."""
    import casadi as ca

    from risk_env import Belief
    from risk_env.models.ops import NUMPY
    from risk_env.risk.quadrature import SOLVER_SHORTFALL

    epsilon = 1000.0
    env = gym.make("RiskCrossing-v0", uncertainty="medium", risk_tolerance=epsilon)
    scenario = env.unwrapped.scenario
    agent = SMPC.from_env(env, max_solve_time=UNCAPPED)
    exact, box = make_estimator("exact", scenario), make_estimator("worst_case", scenario)
    e, b, eps = ca.SX.sym("e", 4), ca.SX.sym("b", Belief.SIZE), ca.SX.sym("eps")
    numbers = ca.DM([[1.0, scenario.collision_distance, scenario.object.mass]])
    margin = agent._margin(e, [Belief.from_array(b)], eps, ca.SX(0, 0), ca.SX(numbers), False)
    row = ca.Function("row", [e, b, eps], [margin, ca.jacobian(margin, e)])

    def numpy_row(ego: np.ndarray, beliefs) -> np.ndarray:
        clearance = box.distance(ego, beliefs) - box.radius
        return np.maximum(clearance, (epsilon - exact.risk(ego, beliefs)) / exact.severity.scale)

    obs, _ = env.reset(seed=0)
    checked, errors = 0, []
    for _ in range(12):
        action, _ = agent.predict(obs)
        report = agent.last_solve
        beliefs = predict_array(scenario, ob.split(obs).object_measurement)[1:]
        ego = np.column_stack([report.ego_trajectory[1:], report.inputs[:, 0]])
        values, jacobian = (np.asarray(a) for a in row.map(len(ego))(ego.T, beliefs.as_array().T, epsilon))
        expected = np.asarray(exact.severity.expected(ego[:, 3], ego[:, 2], beliefs, NUMPY))
        slack = SOLVER_SHORTFALL * expected / exact.severity.scale
        assert np.all(values.ravel() <= numpy_row(ego, beliefs) + 1e-9)
        assert np.all(values.ravel() >= numpy_row(ego, beliefs) - slack - 1e-9)
        risky = exact.risk(ego, beliefs) > 1.0  # the risk branch of the row is the active one
        got, fd = [], []
        for axis in (0, 1, 3):  # c1, c2, v (theta does not enter the paper's severity)
            step = np.zeros(4)
            step[axis] = 1e-5
            fd.append((numpy_row(ego + step, beliefs) - numpy_row(ego - step, beliefs)) / 2e-5)
            got.append(jacobian.reshape(len(ego), 4)[:, axis])
        got, fd = np.array(got)[:, risky], np.array(fd)[:, risky]
        error = np.linalg.norm(got - fd, axis=0) / np.linalg.norm(fd, axis=0)
        assert np.all(error < 2e-2), error
        errors += list(error)
        checked += int(risky.sum())
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    assert checked >= 10  # plans that take risk were checked
    assert np.median(errors) < 1e-3
