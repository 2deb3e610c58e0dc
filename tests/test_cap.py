"""A real-time cap that holds for every solver call (agents.mpc.nlp.calls): the settings that never returned,
the scaling that keeps fatrop's inertia correction finite, the bounds' split, per-call reports,
strict iteration limits, and budgets and weights out of range rejected by name.

Judged by iterations (``tests/conftest.py`` makes every process strict: a call past its rung's
limit raises :class:`agents.mpc.nlp.calls.IterationLimitError`), never by wall time. The settings that hung
before the fix hang the test rather than fail it: the row-scaling test below fails cleanly on the
same cause."""

from __future__ import annotations

import math
from types import SimpleNamespace

import casadi as ca
import gymnasium as gym
import numpy as np
import pytest

import risk_env  # noqa: F401  (registers RiskCrossing-v0)
from agents import SMPC
from agents.mpc import guesses
from agents.mpc.nlp import calls
from agents.mpc.nlp import risk_budget as rb
from agents.mpc.nlp.budget import Budget
from agents.mpc.step import Step
from risk_env.risk.severity import make_severity
from risk_env.scenario import Scenario

ROW_GRADIENT = 1e2
"""Largest gradient norm of any row of the NLP: fatrop's inertia correction cannot end once a row's
gradient is about 1e3 (agents.mpc.nlp.calls); the risk rows' own are about 1."""


def scale_of(severity: str) -> float:
    return make_severity(Scenario(severity=severity)).scale


def run_steps(agent, env, seed: int, steps: int) -> list:
    """``steps`` steps of ``agent`` from ``env.reset(seed)``: every step's calls."""
    obs, _ = env.reset(seed=seed)
    agent.reset()
    out = []
    for _ in range(steps):
        action, _ = agent.predict(obs)
        out.extend(agent.last_solve.calls)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    return out


def assert_within_limits(records, some: bool = True) -> None:
    """Every call within its rung's limit; ``some``: at least one call was made (uncapped runs
    only: under the cap a loaded machine may leave no time for any)."""
    assert records or not some, "no solver call was made"
    for c in records:
        assert not c.overran, c
        assert c.iterations <= c.limit + 1 and c.wall_time >= 0.0 and c.cpu_time >= 0.0


def close_object_observation(env, seed: int) -> np.ndarray:
    """The first observation of a scene whose object starts 4 m ahead of the ego, crossing."""
    sc = env.unwrapped.scenario
    x, y, theta = sc.ego.start.as_tuple()
    ahead = (x + 4.0 * math.cos(theta), y + 4.0 * math.sin(theta), theta + math.pi / 2)
    close = gym.make("RiskCrossing-v0", scenario=sc.replace(object_start=ahead, object_speed=1.0))
    return close.reset(seed=seed)[0]


def row_gradients(agent, obs: np.ndarray) -> dict[str, float]:
    """The largest gradient norm of each kind of row over the first step's cold guesses."""
    data = agent._measure(0, np.asarray(obs, float))
    step = Step(agent._context(data), data, Budget(math.inf))
    pr = agent._problem(step.variant)
    jac = pr.solver.get_function("nlp_jac_g")
    out: dict[str, float] = {}
    for w0, _ in guesses.cold_guesses(pr, agent.scenario, step.x0, step.p, step.lbg(pr)):
        J = np.asarray(ca.DM(jac(w0, step.p)[1]).full())
        for i, (_, kind, _) in enumerate(pr.g_tags):
            out[kind] = max(out.get(kind, 0.0), float(np.linalg.norm(J[i])))
    return out


# ----------------------------------------------------------------------------- the settings that hung
@pytest.mark.parametrize("allocation", ["horizon", "share"])
def test_the_budget_that_never_returned_now_solves_within_its_limits(allocation: str) -> None:
    """Issue 21: ``risk_budget=0.01`` (paper severity, J) at medium uncertainty, seed 20011: the first
    call never returned (the NLP's budget row, ``"horizon"``, had a gradient of 1.5e4). Uncapped:
    one rung of 150."""
    env = gym.make("RiskCrossing-v0", uncertainty="medium")
    agent = SMPC.from_env(env, risk_budget=0.01, budget_allocation=allocation, max_solve_time=math.inf)
    records = run_steps(agent, env, seed=20011, steps=3)
    assert_within_limits(records)
    if allocation == "horizon":
        assert {c.variant for c in records} <= {"zero", "zero_soft", "free"}
    report = agent.last_solve  # every step reports each of its calls
    assert report.iterations == sum(c.iterations for c in report.calls)
    assert report.overran_calls == 0 and report.failed_calls == sum(not c.success for c in report.calls)


@pytest.mark.slow
def test_the_budget_under_the_default_cap_keeps_every_rung_limit() -> None:
    """The same setting under the default 100 ms cap: each call at the rung the budget chose, within
    that rung's iteration limit (which rungs run depends on the machine; the limits do not)."""
    env = gym.make("RiskCrossing-v0", uncertainty="medium")
    agent = SMPC.from_env(env, risk_budget=0.01, budget_allocation="horizon")
    records = run_steps(agent, env, seed=20011, steps=3)
    assert_within_limits(records, some=False)
    limits = dict(enumerate(lim for lim, _ in agent._problem("zero").limits))
    assert all(c.limit == limits[c.rung] for c in records if c.variant == "zero")


@pytest.mark.parametrize(
    "severity",
    ["paper", *(pytest.param(s, marks=pytest.mark.slow) for s in ("plastic", "probability", "injury"))],
)
def test_every_row_keeps_the_risk_rows_scale(severity: str) -> None:
    """The cause: a row (or dynamics row) whose gradient reaches about 1e3 leaves fatrop's inertia
    correction without end. With the object 4 m ahead, the smallest and the largest budget and the
    heaviest weight keep every row's gradient norm within ROW_GRADIENT (it was 1.5e4 for the
    budget row with B = 0.01 J: its normaliser was 1/B)."""
    scale = scale_of(severity)
    env = gym.make("RiskCrossing-v0", uncertainty="medium", severity=severity)
    obs = close_object_observation(env, seed=3)
    for budget in (rb.MIN_BUDGET * scale, rb.MAX_BUDGET * scale):
        agent = SMPC.from_env(
            env,
            risk_budget=budget,
            budget_allocation="horizon",
            risk_weight=rb.MAX_WEIGHT / scale,
            risk_tolerance=math.inf,
            max_solve_time=math.inf,
        )
        gradients = row_gradients(agent, obs)
        assert {"risk", "budget", "accumulate", "gap"} <= set(gradients)
        assert max(gradients.values()) <= ROW_GRADIENT, gradients


def test_budget_row_holds_iff_the_plan_keeps_the_spare() -> None:
    """nu = 1/scale whatever B: the row at the plan's bound is exactly the backoff."""
    for budget, scale in ((0.01, 1000.0), (3e4, 1000.0), (0.3, 1.0), (2e-7, 0.01)):
        shifted, spent, nu, off, _ = rb.terms_parameters(budget, 0.25 * budget, None, scale, 1e-3)
        assert nu == 1.0 / scale and off == 0.0
        edge = budget - 1e-3 * budget - rb.RESOLUTION * scale  # spent + sum_n R_n at the bound
        assert (shifted - edge) * nu == pytest.approx(1e-3, rel=1e-9)


# ----------------------------------------------------------------------------- named rejections
@pytest.mark.parametrize(
    ("name", "value", "severity"),
    [
        ("risk_weight", 1e300, "paper"),
        ("risk_weight", 1.1e6, "probability"),
        ("risk_budget", 1e-300, "paper"),
        ("risk_budget", 1e300, "paper"),
        ("risk_budget", 5e-8, "injury"),
        ("risk_budget", 2e6, "probability"),
    ],
)
def test_budgets_and_weights_out_of_range_are_named(name: str, value: float, severity: str) -> None:
    with pytest.raises(ValueError, match=rf"{name} must be .*severity's scale of {scale_of(severity):g}"):
        SMPC(Scenario.preset("medium", severity=severity), **{name: value})


@pytest.mark.parametrize("severity", ["paper", "injury"])
def test_the_range_ends_are_accepted(severity: str) -> None:
    scale = scale_of(severity)
    for budget in (0.0, rb.MIN_BUDGET * scale, rb.MAX_BUDGET * scale):
        assert rb.check_budget(budget, scale=scale) == budget
    assert rb.check_weight(rb.MAX_WEIGHT / scale, scale=scale) == rb.MAX_WEIGHT / scale


# ----------------------------------------------------------------------------- calls, limits, split
class FakeSolver:
    """Stands for an nlpsol Function: returns zeros and reports ``iterations``."""

    def __init__(self, iterations: int) -> None:
        self.iterations = iterations

    def __call__(self, **args):
        n = len(args["x0"])
        return {"x": np.zeros(n), "lam_x": np.zeros(n), "lam_g": np.zeros(1), "f": np.zeros(1)}

    def stats(self):
        return {"iter_count": self.iterations, "success": True, "unified_return_status": "SOLVER_RET_SUCCESS"}


def fake_problem(iterations: int, limit: int = 8):
    lbx, ubx, lbg, ubg = np.array([0.0, -1.0]), np.array([0.0, np.inf]), np.zeros(1), np.full(1, np.inf)
    args = {"x0": np.zeros(2), "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg, "p": np.zeros(0)}
    problem = SimpleNamespace(
        variant="general",
        solvers=(FakeSolver(iterations),),
        limits=((limit, None),),
        pattern=calls.bound_pattern(lbx, ubx, lbg, ubg),
    )
    return problem, args


def test_a_call_past_its_limit_raises_in_strict_mode_and_is_counted_otherwise() -> None:
    problem, args = fake_problem(iterations=31)
    with calls.strict_iterations(True), pytest.raises(calls.IterationLimitError, match="31 iterations"):
        calls.call_solver(problem, args, "fatrop")
    with calls.strict_iterations(False):
        assert calls.call_solver(problem, args, "fatrop")[3] == 31
    problem, args = fake_problem(iterations=9)  # fatrop counts one beyond max_iter = 8
    with calls.strict_iterations(True):
        assert calls.call_solver(problem, args, "fatrop")[2]


def test_tests_run_strict() -> None:
    assert calls.strict()


def test_a_call_whose_bounds_split_otherwise_is_refused() -> None:
    """lb = ub makes an entry an equality, both infinite drops it: either change of the split would
    leave CasADi's fatrop plugin on its default options for good."""
    problem, args = fake_problem(iterations=3)
    for change in ({"ubx": np.array([1.0, np.inf])}, {"lbx": np.array([0.0, -np.inf])}):
        with pytest.raises(calls.BoundPatternError, match="general"):
            calls.call_solver(problem, {**args, **change}, "fatrop")
    same_split = {"lbx": np.array([2.0, 5.0]), "ubx": np.array([2.0, 7.0])}  # other values, same split
    assert calls.call_solver(problem, {**args, **same_split}, "fatrop")[2]


def test_the_stress_family_is_seeded_and_within_range() -> None:
    """``stress --family cap``: reproducible, every group and severity, no setting out of range."""
    from benchmarks import cap_family
    from benchmarks.scenes import make_scenes

    scenes = make_scenes(60, seed=2)
    family = cap_family.make_settings(list(cap_family.GROUPS), 60, 2, scenes)
    assert family == cap_family.make_settings(list(cap_family.GROUPS), 60, 2, scenes)
    assert {s.group for s in family} == set(cap_family.GROUPS)
    assert {s.severity for s in family} == set(cap_family.SEVERITIES)
    for s in family:
        scale = scale_of(s.severity)
        assert rb.check_budget(s.budget, scale=scale) == s.budget
        assert rb.check_weight(s.weight, scale=scale) == s.weight
        assert s.group != "rmpc" or (s.budget is None and s.weight is None)
        assert math.isfinite(s.epsilon) or s.budget is not None


# ----------------------------------------------------------------------------- the family (slow)
REALISTIC = [
    (level, budget, tolerance)
    for level in ("low", "medium", "high")
    for budget in (0.05, 1.0, 100.0)
    for tolerance in (0.0, math.inf)
]


@pytest.mark.slow
@pytest.mark.parametrize(("level", "budget", "tolerance"), REALISTIC)
def test_the_realistic_budgets_keep_every_limit(level: str, budget: float, tolerance: float) -> None:
    """Issue 21's 18 settings (one hung at its third step), under the default cap, 8 steps."""
    env = gym.make("RiskCrossing-v0", uncertainty=level)
    agent = SMPC.from_env(env, risk_budget=budget, risk_tolerance=tolerance, budget_allocation="horizon")
    assert_within_limits(run_steps(agent, env, seed=20011, steps=8), some=False)


FAMILY = [
    (severity, level, budget, weight, seed)
    for i, severity in enumerate(("paper", "plastic", "probability", "injury"))
    for j, level in enumerate(("low", "medium", "high"))
    for budget, weight in ((1e-5, None), (5e-5, 1e-3), (1e-3, None), (0.1, 1.0), (1e6, 1e6), (None, 1e3))
    for seed in (i + 3 * j, 100 + i + 3 * j)
]


@pytest.mark.slow
@pytest.mark.parametrize(("severity", "level", "budget", "weight", "seed"), FAMILY)
def test_the_family_keeps_every_limit(severity, level, budget, weight, seed) -> None:
    """Budgets and weights in scales of each severity (from the smallest budget to the largest and
    the heaviest weight), every level, two seeds each; the budget alone (no per-step bound) or
    with the weight under epsilon = one scale; 12 steps, uncapped (one rung of 150 iterations:
    every call runs, whatever the machine's load)."""
    scale = scale_of(severity)
    env = gym.make("RiskCrossing-v0", uncertainty=level, severity=severity)
    options = {"risk_tolerance": math.inf if weight is None else scale}
    if budget is not None:  # the NLP's budget row on one seed, the default share on the other
        options["risk_budget"] = budget * scale
        options["budget_allocation"] = "horizon" if seed < 100 else "share"
    if weight is not None:
        options["risk_weight"] = weight / scale
    agent = SMPC.from_env(env, max_solve_time=math.inf, **options)
    assert_within_limits(run_steps(agent, env, seed=seed, steps=12))


def test_a_monte_carlo_pilot_takes_a_budgets_bound_within_the_severitys_largest_risk() -> None:
    """A budget of 1e6 (allowed: 1e6 scales) under the probability severity and no per-step bound
    gives an effective bound above 1; the Monte Carlo pilot plans within 1, the largest per-step
    probability, instead of raising (it did, in the cap family's setting 218)."""
    env = gym.make("RiskCrossing-v0", uncertainty="high", severity="probability")
    agent = SMPC.from_env(
        env,
        risk="monte_carlo",
        samples=20,
        pilot_samples=10,
        risk_budget=1e6,
        risk_tolerance=math.inf,
        max_solve_time=math.inf,
    )
    obs, _ = env.reset(seed=2)
    action, _ = agent.predict(obs)
    assert np.all(np.isfinite(action)) and agent._pilot.risk_tolerance == 1.0


def test_a_capped_agent_builds_at_construction_every_nlp_a_step_can_run() -> None:
    """A build inside a step took 0.3 to 1.3 s against a 100 ms cap (the stress family's steps over
    the cap): a capped agent prepares at construction, so that ``prepare()`` then builds nothing;
    uncapped, the same agent builds the shared budget's zero-tolerance form lazily (so the counter
    can fail this test)."""
    from agents.mpc.nlp import solver

    scenario = Scenario.preset("low", severity="probability").replace(horizon=3)
    options = {"risk_budget": 0.05, "risk_tolerance": math.inf}
    lazy = SMPC(scenario, max_solve_time=math.inf, **options)
    built = solver.CACHE_COUNTS.builds
    assert lazy.prepare() > 0 and solver.CACHE_COUNTS.builds > built
    capped = SMPC(scenario, max_solve_time=0.1, **options)
    built = solver.CACHE_COUNTS.builds
    assert capped.prepare() == 0.0 and solver.CACHE_COUNTS.builds == built


def test_the_monte_carlo_pilot_is_built_in_the_form_it_runs() -> None:
    """The pilot runs at the agent's positive tolerance only (the ``"general"`` form), whatever the
    scenario's tolerance: it is built so, at construction when capped."""
    from agents.mpc.nlp import solver

    scenario = Scenario.preset("low", severity="probability", risk_tolerance=0.0).replace(horizon=3)
    agent = SMPC(
        scenario, risk="monte_carlo", samples=40, pilot_samples=20, risk_tolerance=0.01, max_solve_time=0.1
    )
    assert {v for v, _ in agent._pilot._problems} == {"free", "general", "general_soft"}
    built = solver.CACHE_COUNTS.builds
    assert agent.prepare() == 0.0 and solver.CACHE_COUNTS.builds == built
