r"""One step of the MPC (:class:`agents.PathFollowingMPC`), a pipeline: from what the controller
measured (:class:`StepInput`) and what it owns (:class:`StepContext`), the levels below; the result
(:class:`StepResult`) says what the controller is to remember. The step never reaches back into the
controller.

**Graceful degradation**, in this order, each step (never raising inside an episode, never
returning NaN; :attr:`agents.PathFollowingMPC.last_solve` says which level acted):

(a) the hard problem: warm-started from the shifted previous plan (an episode's first step:
    from each of the best initial-guess rollouts, up to ``cold_starts``, keeping the plan of
    least cost). A success is IPOPT's "Solve_Succeeded" or "Solved_To_Acceptable_Level",
    fatrop's success flag, with finite numbers.
(b) if none converges (infeasible, iteration or time limit, NaN, an exception): the same
    problem with its risk rows softened by L1-penalised slacks (the ``"*_soft"`` variants of
    :mod:`agents.mpc.nlp.ocp`), from the shifted plan, then the best rollouts and manoeuvres (up to
    ``cold_starts``; they replace the hard problem's cold retries). The penalty is
    exact: where the hard problem is feasible (and $\rho$ exceeds its risk rows' multipliers) the
    soft problem's solution is the hard one's, with zero slacks. So a soft plan whose slacks
    vanish (to :data:`FEASIBLE_SLACK`) solves the hard problem, and is level (a)
    (``fallback=None``, ``retried=True``, ``variant="*_soft"``). Otherwise the soft plan, the
    least violation of the risk bound the solver found (so the most clearance it could keep),
    is applied: ``fallback="soft"`` with the ``violation``.
    After a step whose soft plan missed the risk bound the next step goes to the soft problem
    directly, from the shifted plan only ("elastic mode", as in SNOPT): the hard problem is
    most likely infeasible still, and where it is not, its exact penalty returns its solution.
(c) if that fails too: the safest of a family of rate-limited manoeuvres (brake, hold,
    accelerate, reverse, each straight or turning fully left or right, and with a corridor
    following the path; :mod:`agents.mpc.fallback`), judged by the agent's own risk, the corridor
    and the worst-case clearance over the horizon: ``fallback="manoeuvre"``.

**Real-time bound**: a step takes at most ``max_solve_time`` of wall time (by default 20 % of the
sample time), enforced through the solver's own limits: each NLP is built at a few rungs of
iteration limits (fatrop: ``max_iter / 2**r``) or wall-time limits (IPOPT: ``max_wall_time =
max_solve_time / 2**r``), and each call runs at the largest rung that fits the time left,
judged from the measured time per iteration (:mod:`agents.mpc.nlp.budget`). The hard problem's calls
leave :data:`SOFT_SHARE` of the cap to the soft problem, which leaves the manoeuvres their
(small, measured) time. When no rung fits, the next level acts.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from agents.base import CallRecord, SolveReport
from agents.mpc import attempts, fallback, guesses
from agents.mpc.attempts import Call, Guess, Tally
from agents.mpc.fallback import feasible_action
from agents.mpc.nlp.bounds import variable_bounds
from agents.mpc.nlp.budget import Budget
from agents.mpc.nlp.corridor import step_bounds, step_widths
from agents.mpc.nlp.ocp import soft_variant
from agents.mpc.nlp.settings import SolverSettings
from agents.mpc.nlp.solver import Problem
from risk_env.prediction.belief import Belief
from risk_env.risk.estimators import WorstCaseRisk
from risk_env.scenario.scenario import Scenario

SOFT_SHARE = 0.3
"""Most of the cap the hard problem's calls leave to the soft problem."""
OPTIONAL_SHARE = 0.1
"""Share of the cap kept free by the soft level's further starts once one plan converged."""
SOFT_ITERATIONS = 30
"""Iterations a soft solve is given time for, before the hard problem's calls."""
FEASIBLE_SLACK = 1e-4
"""Slacks up to this [margin units] count as zero: the hard problem was feasible."""
CORRIDOR_REENTRY = 0.5
"""How much wider [m] than its start's lateral offset the corridor is for an ego that starts outside
it."""
MANOEUVRE_TIME = 3e-3
"""Time [s] kept for choosing the manoeuvre before it was first measured."""

Outputs = dict[str, np.ndarray]
RiskFunction = Callable[[np.ndarray, list[Belief | None], np.ndarray], np.ndarray]
"""``(ego states (N, 4), each slot's beliefs at n = 1..N or None, risk data) -> risk (N,)``: the
agent's own numpy risk, summed over the present slots."""
Pilot = Callable[[int, np.ndarray, str], tuple[np.ndarray, int, tuple[CallRecord, ...]] | None]
"""``(batch index, observation, variant) -> (inputs (N, NU), iterations, calls) or None``: a cold start's
first initial guess, planned on a cheaper problem (the Monte Carlo SMPC's pilot)."""


@dataclass(frozen=True)
class StepContext:
    """What a step uses that the controller owns: the scenario, the solver settings, the built
    problems, the solver call, the agent's risk and the limits of the levels."""

    scenario: Scenario
    settings: SolverSettings
    problem: Callable[[str], Problem]
    """The built NLP of a variant (the controller's cache)."""
    built: Mapping[str, Problem]
    """The variants built so far (IPOPT's warm start maps multipliers from the last one)."""
    call: Call
    risk: RiskFunction
    worsts: tuple[WorstCaseRisk, ...]
    """Each slot's worst-case estimator (the manoeuvres' clearance)."""
    pilot: Pilot | None
    maps: dict[tuple[str, str, str], np.ndarray]
    """Cache of the multiplier maps between variants (filled as the steps go)."""
    epsilon: float
    backoff: float
    cold_starts: int
    max_solve_time: float
    manoeuvre_time: float
    """Time [s] kept for choosing the manoeuvre (twice its last measured time)."""


@dataclass(frozen=True)
class StepInput:
    r"""What the controller measured for one step: batch entry ``index`` with its observation, its
    memory of the last step (None: a new episode), the state ``x0`` (NX,), each slot's beliefs at
    $n = 1, \dots, N$ (``futures``, None where absent), which slots are ``active``, the NLP ``variant``, the
    risk ``data`` and the parameters ``p``."""

    index: int
    obs_vec: np.ndarray
    memory: dict[str, Any] | None
    x0: np.ndarray
    futures: list[Belief | None]
    active: np.ndarray
    variant: str
    data: np.ndarray
    p: np.ndarray
    weights: np.ndarray | None = None
    """Each row's mode weight w ``(K M,)`` (1 for the paper's prediction)."""
    epsilon: float = 0.0
    """The step's risk tolerance (the agent's, or its share of an episode budget)."""
    rows: int | None = None
    """The rows of beliefs of the NLP that runs (the active rows packed; None: all)."""


@dataclass(frozen=True)
class StepResult:
    """What a step did (``report``) and what the controller is to keep: the batch entry's new
    ``memory``, the measured ``manoeuvre_time`` [s] and whether a fallback acted (``failed``)."""

    report: SolveReport
    memory: dict[str, Any]
    manoeuvre_time: float
    failed: bool


class Step:
    """The levels of one step on ``data`` (:class:`StepInput`) with ``context``
    (:class:`StepContext`) within ``budget``."""

    def __init__(self, context: StepContext, data: StepInput, budget: Budget) -> None:
        self.context, self.budget = context, budget
        self.index, self.obs_vec, self.memory = data.index, data.obs_vec, data.memory
        self.x0, self.futures, self.active = data.x0, data.futures, data.active
        self.variant, self.data, self.p = data.variant, data.data, data.p
        self.base = context.problem("free")
        self.manoeuvre_time = context.manoeuvre_time
        self.stands = attempts.stands(context.settings.restart_standing, data.memory, data.x0)
        self.tally = Tally()

    # ------------------------------------------------------------------ the levels
    def run(self) -> StepResult:
        """The three levels in order; the result of the one that acted."""
        ctx, budget = self.context, self.budget
        budget.reserve = self.manoeuvre_time + self.soft_reserve()
        pr = ctx.problem(self.variant)
        # elastic mode: after a step that missed the risk bound, the hard problem is most likely
        # infeasible still; its exact penalty (b) gives its solution where it is feasible
        last = self.memory.get("violation", 0.0) if self.memory is not None else 0.0
        elastic = self.variant != "free" and last > FEASIBLE_SLACK and not self.stands
        out, retried = (None, False) if elastic else self.hard(pr, budget.reserve)
        kind, violation = None, 0.0
        if out is None and self.variant != "free":
            budget.reserve = self.manoeuvre_time
            soft = ctx.problem(soft_variant(self.variant))
            out, violation = self.soft(soft, elastic)
            if out is not None:
                pr = soft
                if violation <= FEASIBLE_SLACK:  # the exact penalty's solution: the hard problem's
                    violation, retried = 0.0, True
                else:
                    kind = "soft"
        name = ""
        if out is not None:
            lbx, ubx = variable_bounds(ctx.scenario, pr.x_index, pr.u_index, pr.n_w, self.x0, pr.slack_index)
            w = np.clip(out["x"], lbx, ubx)
            states, inputs, cost = w[pr.x_index], w[pr.u_index], float(out["f"][0])
            mem = {"plan": inputs, "lam_x": out["lam_x"], "lam_g": out["lam_g"], "variant": pr.variant}
            mem["violation"] = violation
        else:
            kind = "manoeuvre"
            name, inputs = self.manoeuvre()
            states, cost = guesses.rollout(self.base, self.x0, inputs), float("nan")
            # not elastic after this: nothing converged, maybe for lack of time (the soft problem
            # is no faster), so the next step tries the hard problem again, from this plan
            mem = {"plan": inputs, "lam_x": None, "variant": None, "violation": 0.0, "manoeuvre": True}
        return self.report(pr, kind, states, inputs, cost, mem, violation, name, retried)

    def soft_reserve(self) -> float:
        """Time [s] the hard problem's calls leave to the soft one: what :data:`SOFT_ITERATIONS`
        of its iterations take, if that fits in :data:`SOFT_SHARE` of the cap; else nothing (the
        soft problem could not finish in time anyway, so the hard one gets the time)."""
        cap = self.context.max_solve_time
        if not math.isfinite(cap) or self.variant == "free":
            return 0.0
        times = self.context.problem(soft_variant(self.variant)).times
        need = SOFT_ITERATIONS * times.per_iteration(SOFT_ITERATIONS)
        return need if need <= SOFT_SHARE * cap else 0.0

    def hard(self, pr: Problem, reserve: float) -> tuple[Outputs | None, bool]:
        """Level (a): ``(the best converged call or None, whether it followed a failed call)``.
        An episode's first step solves from every rollout (up to ``cold_starts``) and keeps the
        plan of least cost, unless a pilot plan converged first; a later step solves from the
        shifted plan only (where it stands, with ``restart_standing``, from the rollouts too, keeping
        the cheaper plan): when that fails, the soft problem, from the shifted plan and the cold
        rollouts, gives the hard problem's solution where there is one (the penalty is exact),
        and the least violation where there is none."""
        ctx, mem = self.context, self.memory
        first = mem is None
        warm = not first and mem.get("plan") is not None
        pilot = None if warm or ctx.pilot is None else ctx.pilot
        planned = None if pilot is None else pilot(self.index, self.obs_vec, pr.variant)
        if planned is not None:  # the pilot's plan first; its own cold start chose among the rollouts
            inputs, iterations, pilot_calls = planned
            self.tally.iterations += iterations
            self.tally.calls.extend(pilot_calls)
            w0 = guesses.pack(pr, guesses.rollout(pr, self.x0, inputs), inputs)
            head = [(guesses.fill_accumulators(pr, w0, self.p), None, None)]
            out, calls = self.solve(pr, head, reserve)
            if out is not None or calls == 0:
                return out, False
        # after a manoeuvre its continuation is a poor start for path following: the best
        # rollout first, then that
        after_manoeuvre = warm and mem.get("manoeuvre", False)
        cold, best = not warm or after_manoeuvre or self.stands, first or self.stands
        points = self.guesses(pr, extra=False, cold=cold, cold_first=after_manoeuvre)
        out, _ = self.solve(pr, points, reserve, keep_best=best, reserve_after=self.manoeuvre_time)
        return out, out is not None and self.tally.failed_calls > 0

    def soft(self, soft: Problem, elastic: bool) -> tuple[Outputs | None, float]:
        """Level (b): ``(the soft problem's plan or None, its violation max_n s_n)``: from the
        shifted plan, then (unless ``elastic``: the last step missed the bound too, and its
        plan is the best start) the best rollouts and manoeuvres while the time lasts, until a
        plan without violation (the hard problem's solution); else the plan of least objective,
        so of least (early-weighted) violation."""

        def violation(out: Outputs) -> float:
            return max(float(np.max(out["x"][soft.slack_index])), 0.0)

        def feasible(out: Outputs) -> bool:
            return violation(out) <= FEASIBLE_SLACK

        points = self.guesses(soft, extra=True, cold=not elastic)
        # once a plan is in hand the other starts are optional: they keep a margin of the cap
        reserve = self.manoeuvre_time
        cap = self.context.max_solve_time
        optional = reserve + (OPTIONAL_SHARE * cap if math.isfinite(cap) else 0.0)
        out, _ = self.solve(soft, points, reserve, keep_best=True, reserve_after=optional, enough=feasible)
        return (None, 0.0) if out is None else (out, violation(out))

    def manoeuvre(self) -> tuple[str, np.ndarray]:
        """Level (c): ``(name, inputs (N, NU))`` of the safest manoeuvre (:func:`agents.mpc.fallback.choose`:
        the agent's own risk, the corridor, the worst-case clearance)."""
        ctx, t0 = self.context, time.perf_counter()
        risk = lambda ego: ctx.risk(ego, self.futures, self.data)  # noqa: E731
        rollout = functools.partial(guesses.rollout, self.base, self.x0)
        args = (risk, ctx.worsts, self.futures, ctx.epsilon)
        choice = fallback.choose(ctx.scenario, self.x0, rollout, *args)
        self.manoeuvre_time = max(MANOEUVRE_TIME, 2.0 * (time.perf_counter() - t0))
        return choice

    # ------------------------------------------------------------------ helpers
    def solve(
        self,
        pr: Problem,
        points: Any,
        reserve: float,
        keep_best: bool = False,
        reserve_after: float | None = None,
        enough: Any = None,
    ) -> tuple[Outputs | None, int]:
        """:func:`agents.mpc.attempts.solve` of ``pr`` from ``points`` within the step's budget."""
        args, call, tally = self.args(pr), self.context.call, self.tally
        return attempts.solve(
            call, pr, points, args, self.budget, reserve, tally, keep_best, reserve_after, enough
        )

    def args(self, pr: Problem) -> dict[str, Any]:
        """The nlpsol arguments of ``pr`` but the initial point."""
        lbx, ubx = variable_bounds(
            self.context.scenario, pr.x_index, pr.u_index, pr.n_w, self.x0, pr.slack_index
        )
        return {"lbx": lbx, "ubx": ubx, "lbg": self.lbg(pr), "ubg": self.ubg(pr), "p": self.p}

    def corridor_bounds(self, pr: Problem) -> tuple[np.ndarray, np.ndarray]:
        """The corridor rows' ``(lower, upper)`` bounds: :func:`agents.mpc.nlp.corridor.step_widths`
        (an ego outside the corridor gets :data:`CORRIDOR_REENTRY` more)."""
        x, y, theta, free = self.x0[0], self.x0[1], self.x0[2], pr.variant == "free"
        width = step_widths(self.context.scenario, x, y, pr.soft, free, CORRIDOR_REENTRY, theta)
        rows = pr.corridor_rows
        return step_bounds(pr.lbg[rows], pr.ubg[rows], width[[pr.g_tags[i][0] - 1 for i in rows]])

    def lbg(self, pr: Problem) -> np.ndarray:
        """The rows' lower bounds, the risk rows' at the back-off."""
        lbg = pr.lbg.copy()
        lbg[pr.risk_rows] = self.context.backoff
        if pr.corridor_rows.size:
            lbg[pr.corridor_rows] = self.corridor_bounds(pr)[0]
        return lbg

    def ubg(self, pr: Problem) -> np.ndarray:
        """The rows' upper bounds (the corridor's as :meth:`corridor_bounds`)."""
        if not pr.corridor_rows.size:
            return pr.ubg
        ubg = pr.ubg.copy()
        ubg[pr.corridor_rows] = self.corridor_bounds(pr)[1]
        return ubg

    def guesses(
        self, pr: Problem, extra: bool, cold: bool = True, cold_first: bool = False
    ) -> Iterator[Guess]:
        """Initial points, lazily: the shifted previous plan (if any), then (``cold``) the cold
        rollouts best first, up to ``cold_starts`` (``extra``: the manoeuvres ranked with them); for
        the hard problem only the best when even that one misses its rows (then the hard problem
        is likely infeasible, and the soft one takes the other starts). ``cold_first``: the best
        rollout, then the shifted plan."""
        ctx, mem, lbg = self.context, self.memory, self.lbg(pr)
        warm: list[Guess] = []
        if mem is not None and mem.get("plan") is not None:
            ipopt = ctx.settings.warm_start and ctx.settings.solver == "ipopt"
            old = ctx.built.get(mem["variant"]) if ipopt else None
            warm = [attempts.warm_guess(pr, old, mem, self.x0, self.p, lbg, ctx.maps)]
        if not cold_first:
            yield from warm
        if cold:
            more = fallback.manoeuvres(ctx.scenario, self.x0) if extra else None
            cold_points = guesses.cold_guesses(pr, ctx.scenario, self.x0, self.p, lbg, more)
            likely_infeasible = not pr.soft and cold_points[0][1] > 0.0  # even the best misses its rows
            for w0, _ in cold_points[: 1 if likely_infeasible or cold_first else ctx.cold_starts]:
                yield w0, None, None
        if cold_first:
            yield from warm

    def report(
        self,
        pr: Problem,
        kind: str | None,
        states: np.ndarray,
        inputs: np.ndarray,
        cost: float,
        mem: dict[str, Any],
        violation: float,
        name: str,
        retried: bool,
    ) -> StepResult:
        """Apply the plan's first input (clipped into the rate limits), remember the plan, report."""
        ctx, x0 = self.context, self.x0
        action = feasible_action(ctx.scenario, inputs[0, :2], x0[4:6])
        if kind is not None:
            if not np.allclose(action, inputs[0, :2]):  # the rate limits cut the first input
                inputs = inputs.copy()
                inputs[0, :2] = action
                states = guesses.rollout(self.base, x0, inputs)
        action = action.astype(np.float32)
        mem["action"] = action
        mem["predicted"] = states[1, :2].copy()
        ego_states = states[1:, [0, 1, 2, 4]]  # pose of state n with the speed v_{n-1} that led there
        tally = self.tally
        report = SolveReport(
            solve_time=time.perf_counter() - self.budget.start,
            cpu_time=time.process_time() - self.budget.cpu_start,
            success=kind != "manoeuvre",
            status=tally.status if kind != "manoeuvre" else f"manoeuvre {name} ({tally.status})",
            iterations=tally.iterations,
            fallback=kind,
            action=action,
            ego_trajectory=states[:, :3].copy(),
            inputs=inputs[:, :2].copy(),
            path_speed=inputs[:, 2].copy(),
            lambdas=states[:, 3].copy(),
            risk_fn=functools.partial(ctx.risk, ego_states, self.futures, self.data),
            risk_tolerance=ctx.epsilon,
            cost=cost,
            retried=retried,
            solver_time=tally.solver_time,
            variant=pr.variant if kind != "manoeuvre" else self.variant,
            timings=tally.timings,
            violation=violation,
            manoeuvre=name,
            failed_calls=tally.failed_calls,
            overran_calls=tally.overran_calls,
            capped=self.budget.capped,
            calls=tuple(tally.calls),
        )
        return StepResult(report, mem, self.manoeuvre_time, kind is not None)
