"""Solving one NLP within a step's time budget: the warm start, and one solver call per initial
guess, each at the largest rung (:meth:`agents.mpc.nlp.settings.SolverSettings.rung_limits`) that fits the
time left, until one converges (or, for an episode's first step, every guess ran and the plan of
least cost is kept)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agents.base import CallRecord
from agents.mpc import guesses
from agents.mpc.nlp.budget import Budget
from agents.mpc.nlp.solver import Problem

Guess = tuple[np.ndarray, np.ndarray | None, np.ndarray | None]
"""An initial point: w ``(n_w,)`` and, for IPOPT's warm start, the multipliers lam_x and lam_g."""
STANDING = 0.1
"""Speed [m/s] below which the ego and a planned input stand (:func:`stands`)."""
TIME_LIMITED = ("Maximum_WallTime_Exceeded", "Maximum_CpuTime_Exceeded")
"""IPOPT's return statuses at its time limits."""
Outcome = tuple[dict[str, np.ndarray], str, bool, int, dict[str, float]]
Call = Callable[[Problem, dict[str, Any], int], Outcome]
"""``(problem, nlpsol arguments, rung) -> (outputs, status, success, iterations, wall times)``."""


@dataclass
class Tally:
    """What the solver calls of one step did."""

    iterations: int = 0
    """Iterations, summed over the calls."""
    failed_calls: int = 0
    """Calls that did not converge."""
    overran_calls: int = 0
    """Calls that ran more iterations than their rung allows (the solver ignored its limit)."""
    solver_time: float = 0.0
    """Wall time inside the calls [s]."""
    status: str = "not solved"
    """Return status of the last call."""
    timings: dict[str, float] = field(default_factory=dict)
    """Solver-internal wall times [s] of the last call."""
    calls: list[CallRecord] = field(default_factory=list)
    """Every call, in order (a pilot problem's first)."""


def solve(
    call: Call,
    problem: Problem,
    guesses: Iterable[Guess],
    args: dict[str, Any],
    budget: Budget,
    reserve: float,
    tally: Tally,
    keep_best: bool = False,
    reserve_after: float | None = None,
    enough: Callable[[dict[str, np.ndarray]], bool] | None = None,
) -> tuple[dict[str, np.ndarray] | None, int]:
    """``(outputs of the converged call of least objective or None, calls made)``: one call of
    ``problem`` per guess (``args``: the nlpsol arguments but the initial point), while a rung
    fits the budget left beyond ``reserve`` [s] (``reserve_after`` once a call converged: the later
    levels will not run); stops at the first success unless ``keep_best``, and then at the first
    success that is ``enough``."""
    best: dict[str, np.ndarray] | None = None
    calls = 0
    points = iter(guesses)
    while True:
        rung = problem.times.rung(budget.left(reserve))  # before the next guess is computed
        point = next(points, None) if rung is not None else None
        if point is None:
            budget.capped |= rung is None
            break
        w0, lam_x, lam_g = point
        rung = problem.times.rung(budget.left(reserve))  # the guess took time too
        if rung is None:
            budget.capped = True
            break
        arguments = {**args, "x0": w0}
        if lam_x is not None:
            arguments.update(lam_x0=lam_x, lam_g0=lam_g)
        t0, c0 = time.perf_counter(), time.process_time()
        out, status, ok, iterations, timings = call(problem, arguments, rung)
        elapsed = time.perf_counter() - t0
        limit = problem.limits[rung][0]
        record = CallRecord(
            getattr(problem, "variant", ""),
            rung,
            limit,
            iterations,
            elapsed,
            time.process_time() - c0,
            status,
            ok,
        )
        tally.calls.append(record)
        problem.times.record(iterations, elapsed)
        calls += 1
        tally.iterations += iterations
        tally.solver_time += elapsed
        if ok and (best is None or out["f"][0] < best["f"][0]):
            best = out
            tally.status, tally.timings = status, timings
        elif best is None:
            tally.status, tally.timings = status, timings
        tally.failed_calls += not ok
        tally.overran_calls += record.overran
        # the budget cut this call short: it stopped at a smaller rung's iteration or time limit
        stopped = iterations >= limit or status in TIME_LIMITED
        budget.capped |= not ok and rung > 0 and stopped
        if ok and (not keep_best or (enough is not None and enough(out))):
            break
        if ok and reserve_after is not None:
            reserve = reserve_after
    return best, calls


def shift_map(
    old: Problem, new: Problem, kind: str, cache: dict[tuple[str, str, str], np.ndarray]
) -> np.ndarray:
    """For each entry of ``new``'s w (``kind="w"``) or g (``"g"``), the entry of ``old`` one stage
    later, else at the same stage (-1: none); kept in ``cache``."""
    key = (old.variant, new.variant, kind)
    if key not in cache:
        old_tags, new_tags = (old.w_tags, new.w_tags) if kind == "w" else (old.g_tags, new.g_tags)
        where = {tag: i for i, tag in enumerate(old_tags)}
        cache[key] = np.array(
            [where.get((s + 1, k, c), where.get((s, k, c), -1)) for s, k, c in new_tags], dtype=int
        )
    return cache[key]


def warm_guess(
    problem: Problem,
    old: Problem | None,
    memory: dict[str, Any],
    x0: np.ndarray,
    p: np.ndarray,
    lbg: np.ndarray,
    cache: dict[tuple[str, str, str], np.ndarray],
) -> Guess:
    """The previous plan ``memory["plan"]`` ``(N, NU)`` shifted by one stage (the last input
    repeated), states re-simulated from ``x0`` (a soft variant: slacks where the rows fall short);
    with ``old``, the problem that planned it, also its multipliers ``memory["lam_x"]``,
    ``memory["lam_g"]`` shifted (IPOPT's warm start)."""
    shifted = np.vstack([memory["plan"][1:], memory["plan"][-1:]])
    if problem.slack_index.size:
        w0 = guesses.initial_point(problem, x0, shifted, p, lbg)[0]
    else:
        w0 = guesses.pack(problem, guesses.rollout(problem, x0, shifted), shifted)
        w0 = guesses.fill_accumulators(problem, w0, p)
    if old is None or memory.get("lam_x") is None:
        return w0, None, None
    lam = []
    for kind, values in (("w", memory["lam_x"]), ("g", memory["lam_g"])):
        where = shift_map(old, problem, kind, cache)
        lam.append(np.where(where >= 0, values[np.maximum(where, 0)], 0.0))
    return w0, lam[0], lam[1]


def stands(restart: bool, memory: dict[str, Any] | None, x0: np.ndarray) -> bool:
    """Whether a step restarts a standing plan (``restart``: the agent's ``restart_standing``): the ego
    at state ``x0`` and every input of its last plan (``memory["plan"]``) stand, below :data:`STANDING`."""
    if not restart or memory is None or memory.get("plan") is None:
        return False
    return abs(float(x0[4])) < STANDING and float(np.max(np.abs(memory["plan"][:, 0]))) < STANDING
