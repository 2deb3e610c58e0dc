"""One step of the MPC (:class:`agents.PathFollowingMPC`): measure, choose the NLP variant, then
degrade gracefully within the step's time budget: (a) the hard problem, (b) the same problem with
softened risk rows, (c) the safest rate-limited manoeuvre."""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from agents import attempts, fallback, guesses
from agents.attempts import Guess, Tally
from agents.base import SolveReport
from agents.budget import Budget
from agents.fallback import feasible_action
from agents.ocp import parameter_vector, soft_variant, variable_bounds
from agents.solver import Problem
from risk_env import observation as ob
from risk_env.prediction import Belief

if TYPE_CHECKING:
    from agents.mpc import PathFollowingMPC

SOFT_SHARE = 0.3
"""Most of the cap the hard problem's calls leave to the soft problem."""
OPTIONAL_SHARE = 0.1
"""Share of the cap kept free by the soft level's further starts once one plan converged."""
SOFT_ITERATIONS = 30
"""Iterations a soft solve is given time for, before the hard problem's calls."""
FEASIBLE_SLACK = 1e-4
"""Slacks up to this [margin units] count as zero: the hard problem was feasible."""
MANOEUVRE_TIME = 3e-3
"""Time [s] kept for choosing the manoeuvre before it was first measured."""

Outputs = dict[str, np.ndarray]


class Step:
    """The data of one step (state ``x0``, parameters ``p``, each slot's beliefs at n = 1..N
    (``futures``, None where absent), which slots are ``active``, the budget) and its levels.
    ``agent`` supplies the problems, the solver call and its risk."""

    def __init__(self, agent: PathFollowingMPC, index: int, obs_vec: np.ndarray, budget: Budget) -> None:
        self.agent, self.index, self.obs_vec, self.budget = agent, index, obs_vec, budget
        o = ob.split(obs_vec, slots=agent.slots)
        mem = agent._memory.get(index)
        self.memory = None if mem is not None and agent._new_episode(mem, o) else mem
        self.x0 = agent._measured_state(o)
        self.base = agent._problem("free")
        numbers = agent._numbers
        self.futures: list[Belief | None] = [
            Belief.from_array(np.asarray(self.base.beliefs(o.objects[k], numbers[k, 2:]))[1:])
            if here
            else None
            for k, here in enumerate(o.present)
        ]
        # a slot is active when its object is present and may reach the ego within the horizon
        self.active = np.array(
            [f is not None and agent._risk_possible(self.x0, f, k) for k, f in enumerate(self.futures)]
        )
        self.variant = agent._risk_variant() if self.active.any() else "free"
        self.data = agent._risk_data(self.futures)
        terms = agent._terms_parameters(index, self.memory is None)
        v_ref = agent.scenario.ego.v_ref
        self.p = parameter_vector(agent._epsilon, v_ref, o.objects, self.active, numbers, self.data, terms)
        self.tally = Tally()

    # ------------------------------------------------------------------ the levels
    def run(self) -> SolveReport:
        """The three levels in order; the report of the one that acted."""
        agent, budget = self.agent, self.budget
        budget.reserve = agent._manoeuvre_time + self.soft_reserve()
        pr = agent._problem(self.variant)
        # elastic mode: after a step that missed the risk bound, the hard problem is most likely
        # infeasible still; its exact penalty (b) gives its solution where it is feasible
        last = self.memory.get("violation", 0.0) if self.memory is not None else 0.0
        elastic = self.variant != "free" and last > FEASIBLE_SLACK
        out, retried = (None, False) if elastic else self.hard(pr, budget.reserve)
        kind, violation = None, 0.0
        if out is None and self.variant != "free":
            budget.reserve = agent._manoeuvre_time
            soft = agent._problem(soft_variant(self.variant))
            out, violation = self.soft(soft, elastic)
            if out is not None:
                pr = soft
                if violation <= FEASIBLE_SLACK:  # the exact penalty's solution: the hard problem's
                    violation, retried = 0.0, True
                else:
                    kind = "soft"
        name = ""
        if out is not None:
            lbx, ubx = variable_bounds(
                agent.scenario, pr.x_index, pr.u_index, pr.n_w, self.x0, pr.slack_index
            )
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
        cap = self.agent.max_solve_time
        if not math.isfinite(cap) or self.variant == "free":
            return 0.0
        times = self.agent._problem(soft_variant(self.variant)).times
        need = SOFT_ITERATIONS * times.per_iteration(SOFT_ITERATIONS)
        return need if need <= SOFT_SHARE * cap else 0.0

    def hard(self, pr: Problem, reserve: float) -> tuple[Outputs | None, bool]:
        """Level (a): ``(the best converged call or None, whether it followed a failed call)``.
        An episode's first step solves from every rollout (up to ``cold_starts``) and keeps the
        plan of least cost, unless a pilot plan converged first; a later step solves from the
        shifted plan only: when that fails, the soft problem, from the shifted plan and the cold
        rollouts, gives the hard problem's solution where there is one (the penalty is exact),
        and the least violation where there is none."""
        agent, mem = self.agent, self.memory
        first = mem is None
        warm = not first and mem.get("plan") is not None
        planned = None if warm else agent._pilot_plan(self.index, self.obs_vec, pr.variant)
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
        points = self.guesses(pr, extra=False, cold=not warm or after_manoeuvre, cold_first=after_manoeuvre)
        out, _ = self.solve(pr, points, reserve, keep_best=first, reserve_after=agent._manoeuvre_time)
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
        reserve = self.agent._manoeuvre_time
        cap = self.agent.max_solve_time
        optional = reserve + (OPTIONAL_SHARE * cap if math.isfinite(cap) else 0.0)
        out, _ = self.solve(soft, points, reserve, keep_best=True, reserve_after=optional, enough=feasible)
        return (None, 0.0) if out is None else (out, violation(out))

    def manoeuvre(self) -> tuple[str, np.ndarray]:
        """Level (c): ``(name, inputs (N, NU))`` of the safest manoeuvre (:mod:`agents.fallback`),
        by the agent's own risk (summed over the present objects) and the worst-case clearance
        to the nearest of their truncation boxes."""
        agent, x0 = self.agent, self.x0
        t0 = time.perf_counter()
        family = fallback.manoeuvres(agent.scenario, x0)
        ego = np.stack([guesses.rollout(self.base, x0, u)[1:][:, [0, 1, 2, 4]] for u in family.values()])
        risk = np.stack(
            [np.asarray(agent._risk_numpy(e, self.futures, self.data), float).reshape(-1) for e in ego]
        )
        clearance = np.full(risk.shape, np.inf)
        for k, f in enumerate(self.futures):
            if f is not None:
                worst = agent._worsts[k]
                clearance = np.minimum(clearance, worst.distance(ego, f) - worst.radius)
        name = list(family)[fallback.safest(risk, clearance, agent._epsilon)]
        agent._manoeuvre_time = max(MANOEUVRE_TIME, 2.0 * (time.perf_counter() - t0))
        return name, family[name]

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
        """:func:`agents.attempts.solve` of ``pr`` from ``points`` within the step's budget."""
        args, call, tally = self.args(pr), self.agent._call, self.tally
        return attempts.solve(
            call, pr, points, args, self.budget, reserve, tally, keep_best, reserve_after, enough
        )

    def args(self, pr: Problem) -> dict[str, Any]:
        """The nlpsol arguments of ``pr`` but the initial point."""
        lbx, ubx = variable_bounds(
            self.agent.scenario, pr.x_index, pr.u_index, pr.n_w, self.x0, pr.slack_index
        )
        return {"lbx": lbx, "ubx": ubx, "lbg": self.lbg(pr), "ubg": pr.ubg, "p": self.p}

    def lbg(self, pr: Problem) -> np.ndarray:
        """The rows' lower bounds, the risk rows' at the back-off."""
        lbg = pr.lbg.copy()
        lbg[pr.risk_rows] = self.agent.backoff
        return lbg

    def guesses(
        self, pr: Problem, extra: bool, cold: bool = True, cold_first: bool = False
    ) -> Iterator[Guess]:
        """Initial points, lazily: the shifted previous plan (if any), then (``cold``) the cold
        rollouts best first, up to ``cold_starts`` (``extra``: the manoeuvres ranked with them); for
        the hard problem only the best when even that one misses its rows (then the hard problem
        is likely infeasible, and the soft one takes the other starts). ``cold_first``: the best
        rollout, then the shifted plan."""
        agent, mem, lbg = self.agent, self.memory, self.lbg(pr)
        warm: list[Guess] = []
        if mem is not None and mem.get("plan") is not None:
            ipopt = agent.settings.warm_start and agent.settings.solver == "ipopt"
            old = agent._problems.get(mem["variant"]) if ipopt else None
            warm = [attempts.warm_guess(pr, old, mem, self.x0, self.p, lbg, agent._maps)]
        if not cold_first:
            yield from warm
        if cold:
            more = fallback.manoeuvres(agent.scenario, self.x0) if extra else None
            cold_points = guesses.cold_guesses(pr, agent.scenario, self.x0, self.p, lbg, more)
            likely_infeasible = not pr.soft and cold_points[0][1] > 0.0  # even the best misses its rows
            for w0, _ in cold_points[: 1 if likely_infeasible or cold_first else agent.cold_starts]:
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
    ) -> SolveReport:
        """Apply the plan's first input (clipped into the rate limits), remember the plan, report."""
        agent, x0 = self.agent, self.x0
        action = feasible_action(agent.scenario, inputs[0, :2], x0[4:6])
        if kind is not None:
            agent.failures += 1
            if not np.allclose(action, inputs[0, :2]):  # the rate limits cut the first input
                inputs = inputs.copy()
                inputs[0, :2] = action
                states = guesses.rollout(self.base, x0, inputs)
        action = action.astype(np.float32)
        mem["action"] = action
        mem["predicted"] = states[1, :2].copy()
        agent._memory[self.index] = mem
        ego_states = states[1:, [0, 1, 2, 4]]  # pose of state n with the speed v_{n-1} that led there
        tally = self.tally
        return SolveReport(
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
            risk_fn=functools.partial(agent._risk_numpy, ego_states, self.futures, self.data),
            risk_tolerance=agent._epsilon,
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
