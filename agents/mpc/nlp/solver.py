"""Building the MPC's solver from the NLP of :mod:`agents.mpc.nlp.ocp`: options, rungs, caches.

Solvers (:data:`~agents.mpc.nlp.settings.SOLVERS`): ``"fatrop"`` (default; stage-wise structure
detected by CasADi, a Riccati-based interior point method; primal warm start) and ``"ipopt"`` (exact
Hessian, MUMPS, adaptive barrier, primal-dual warm start; IPOPT's "Solved To Acceptable Level"
counts as a success). On the paper's 36 closed loops (``python -m benchmarks.timing``, 2 cores)
fatrop took a median / p95 of 2.1 / 4.6 ms per RMPC step against IPOPT's 6.6 / 20 ms (IPOPT spends
~2.5 ms per call in MUMPS and its own set-up however small the problem), and 6.3 / 23 ms per
exact-SMPC step against 7.2 / 41 ms, neither with a failed solve. The two may settle in different
local optima.

**Compiled solvers** (``jit=True``): the same NLP is assembled once more in MX with the stage
functions (dynamics, pose cost, risk row) called rather than inlined, its functions (the NLP and
the derivatives the solver evaluates) generated as C by :class:`casadi.CodeGenerator`, compiled by
``$CC`` (gcc) at ``-O{jit_opt}`` into a shared library in a private temporary directory and kept in
``jit_cache`` under a hash of the NLP, so later processes load it; nlpsol then runs from the
library (:mod:`agents.mpc.nlp.compiled`). Nothing is written to the working directory and the process never
changes directory.

**Rungs** (:meth:`~agents.mpc.nlp.settings.SolverSettings.rung_limits`): each NLP is built with a
few solvers that differ only in their limits (fatrop: ``max_iter``, halved per rung; IPOPT:
``max_wall_time``, halved per rung), so that a call can be made to fit the time left in a step
(:mod:`agents.mpc.nlp.budget`). The smallest rung is built first and run on the scenario's start:
its time per iteration is the prior of the budget's estimate, and fatrop rungs that could never fit
twice the step's cap are left out. An uncapped problem (``time_limit`` None) is never fitted into a
time: it skips that run (a third of a build) and keeps every rung.

**Caches**: built problems are kept per process (:func:`cached_problem`, keyed by everything that
changes the NLP or the solver), compiled libraries on disk.
"""

from __future__ import annotations

import math
import time
import warnings
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import casadi as ca
import numpy as np

from agents.mpc.nlp.bounds import variable_bounds
from agents.mpc.nlp.budget import CallTimes
from agents.mpc.nlp.calls import BoundPattern, BoundPatternError, bound_pattern
from agents.mpc.nlp.compiled import compiled_library, have_c_compiler
from agents.mpc.nlp.corridor import CORRIDOR_SLACK, corridor_weight
from agents.mpc.nlp.ocp import (
    EARLY_WEIGHT,
    NU,
    NX,
    SOFT,
    Margin,
    RiskValue,
    assemble,
    stage_functions,
)
from agents.mpc.nlp.parameters import parameter_vector, slot_numbers
from agents.mpc.nlp.settings import SolverSettings
from risk_env.models.path import project
from risk_env.scenario.scenario import Scenario

USEFUL_RUNG = 2.0
"""A fatrop rung is built when its iterations at the prior time per iteration take at most this
many step caps (a larger one could never fit the time left in a step)."""
_CACHE_SIZE = 128
_SOLVER_CACHE: OrderedDict[Any, Problem] = OrderedDict()


@dataclass
class CacheCounts:
    """How the process-wide cache (:func:`cached_problem`) answered since the process started:
    problems built (misses) and problems found (hits). A step that built nothing leaves
    ``builds`` as it was (what :meth:`agents.PathFollowingMPC.prepare` is for)."""

    builds: int = 0
    hits: int = 0


CACHE_COUNTS = CacheCounts()
"""The process's :class:`CacheCounts`."""


@dataclass(frozen=True)
class Problem:
    """One built NLP variant: the solver, an evaluator and the index maps of its layout."""

    variant: str
    solvers: tuple[ca.Function, ...]
    """The solver at each rung of :meth:`SolverSettings.rung_limits`, the largest first."""
    limits: tuple[tuple[int, float | None], ...]
    """``(max_iter, max_wall_time [s] or None)`` of each rung."""
    evaluate: ca.Function
    """(w, p) -> (objective, g): scores initial-guess candidates."""
    rollout: ca.Function
    """($x_0$ (NX,), inputs (NU, N)) -> states (NX, N): the model $f$, accumulated."""
    beliefs: ca.Function
    r"""object measurement (5,) -> (N+1, Belief.SIZE) belief fields at $n = 0, \dots, N$
    (``Belief.as_array`` order)."""
    lbg: np.ndarray
    ubg: np.ndarray
    x_index: np.ndarray
    """(N+1, NX) positions of the states in w."""
    u_index: np.ndarray
    """(N, NU) positions of the inputs in w."""
    risk_rows: np.ndarray
    r"""Rows of g holding the risk rows of $n = 1, \dots, N$ (one per stage or one per object slot and stage)
    and the budget's row (empty for ``"free"``)."""
    row_slack: np.ndarray
    """For each of :attr:`risk_rows`, the position of its slack in :attr:`slack_index` (a stage's
    rows share one; empty for hard variants)."""
    slack_index: np.ndarray
    r"""Positions of the slacks $s_n$, $n = 1, \dots, N$ (and the budget row's), in w (empty for hard
    variants)."""
    slack_costs: np.ndarray
    r"""$\rho_n$, the cost of each slack $s_n$, in the order of :attr:`slack_index` (empty for hard
    variants)."""
    w_tags: tuple[tuple[int, str, int], ...]
    """(stage, kind, component) of every entry of w."""
    shift_w: np.ndarray
    """For each entry of w, the same entry one stage later (the last stage: itself)."""
    g_tags: tuple[tuple[int, str, int], ...]
    """(stage, kind, component) of every row of g: maps multipliers between variants and stages."""
    build_time: float
    """Seconds to build (and with jit compile) the solver."""
    jit: bool
    """Whether the solver's functions were compiled."""
    times: CallTimes
    """The rungs' limits and the measured time per iteration (shared by the cached copies)."""
    acc_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    r"""Positions of the budget's accumulators $c_n$, $n = 1, \dots, N$, in w (empty without a budget)."""
    acc_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    r"""Rows of g of $c_{n+1} = c_n + \nu R_n$, $n = 0, \dots, N-1$ (empty without a budget)."""
    corridor_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    r"""Rows of g of the lateral offsets at $n = 1, \dots, N$, within $\pm$ the path's corridor
    (empty without one)."""
    corridor_slack: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    """For each of :attr:`corridor_rows`, the position of its slack in :attr:`slack_index` (a soft
    variant's corridor, :mod:`agents.mpc.nlp.corridor`; else empty)."""
    pattern: BoundPattern | None = None
    """The split of the bounds into equalities and inequalities that every call keeps
    (:func:`agents.mpc.nlp.calls.bound_pattern`; checked by :func:`agents.mpc.nlp.calls.call_solver`)."""

    @property
    def n_w(self) -> int:
        return len(self.w_tags)

    @property
    def solver(self) -> ca.Function:
        """The largest rung's solver."""
        return self.solvers[0]

    @property
    def soft(self) -> bool:
        return self.variant.endswith(SOFT)


def cached_problem(key: tuple[Any, ...], build: Callable[[], Problem]) -> Problem:
    """The process-wide problem under ``key``, built by ``build()`` on a miss (``build_time`` 0 on a
    hit); the least recently used of more than 128 are dropped (an SMPC at the intersection warms up
    about 60: :meth:`agents.PathFollowingMPC.prepare`). Counted in :data:`CACHE_COUNTS`."""
    if key in _SOLVER_CACHE:
        _SOLVER_CACHE.move_to_end(key)
        CACHE_COUNTS.hits += 1
        return replace(_SOLVER_CACHE[key], build_time=0.0)
    CACHE_COUNTS.builds += 1
    problem = build()
    _SOLVER_CACHE[key] = problem
    while len(_SOLVER_CACHE) > _CACHE_SIZE:
        _SOLVER_CACHE.popitem(last=False)
    return problem


def build_problem(
    scenario: Scenario,
    variant: str,
    settings: SolverSettings,
    margin: Margin,
    risk_shape: tuple[int, int],
    value: RiskValue | None = None,
    terms: tuple[bool, bool] = (False, False),
    slots: int = 1,
    given: bool = False,
) -> Problem:
    """Build the NLP of :mod:`agents.mpc.nlp.ocp` for ``variant`` with ``slots`` object slots and its
    solver (compiled with ``settings.jit`` where a C compiler works); ``value`` and ``terms``: the
    risk budget and weight (:func:`agents.mpc.nlp.ocp.assemble`)."""
    t0 = time.perf_counter()
    N = scenario.horizon
    stages = stage_functions(scenario, variant, margin, risk_shape, value, slots, given)
    # the NLP in SX, every stage function inlined (what the solver runs uncompiled)
    penalty = settings.soft_penalty if variant.endswith(SOFT) else None
    nlp, (w_tags, g_tags, lbg, ubg), belief_fn = assemble(
        ca.SX, scenario, stages, risk_shape, settings.stage_cost, penalty, terms, slots, given
    )

    base: dict[str, Any] = {"expand": True, "print_time": False, "error_on_fail": False}
    if settings.solver == "fatrop":
        base["equality"] = [lo == hi for lo, hi in zip(lbg, ubg, strict=True)]
    jit = settings.jit and have_c_compiler()
    if settings.jit and not jit:
        warnings.warn("jit=True but no C compiler was found: building without jit", stacklevel=5)
    oracle: Any = nlp
    if jit:
        # the same NLP in MX, the stage functions called rather than inlined: the generated C
        # code holds the risk row and its derivatives once instead of N times; every rung loads
        # the one library, whose compiled "nlp" leaves nothing to expand
        calls, *_ = assemble(
            ca.MX, scenario, stages, risk_shape, settings.stage_cost, penalty, terms, slots, given
        )
        base["expand"] = False
        library = compiled_library(
            calls,
            {**base, **settings.plugin_options(0)},
            settings.solver,
            settings.jit_opt,
            settings.jit_cache,
        )
        jit = library is not None
        oracle = library if jit else nlp
        base["expand"] = not jit

    derivatives: dict[str, ca.Function] = {}
    generated: dict[str, ca.Function] = {}  # fatrop's: the first rung's derivatives, for the others

    def make(rung: int) -> ca.Function:
        options = {**base, **derivatives, **settings.plugin_options(rung)}
        if generated:
            options["cache"] = generated
        solver = ca.nlpsol("mpc", settings.solver, oracle, options)
        if settings.solver == "ipopt" and not jit and not derivatives:  # IPOPT's rungs share them
            names = {"grad_f": "nlp_grad_f", "jac_g": "nlp_jac_g", "hess_lag": "nlp_hess_l"}
            derivatives.update({k: solver.get_function(v) for k, v in names.items()})
        if settings.solver == "fatrop" and not jit and not generated:  # so do fatrop's
            generated.update(solver.cache())
        return solver

    # the smallest rung first: its time per iteration on the scenario's start is the prior, which
    # leaves out the larger fatrop rungs that could never fit in the cap
    ladder = settings.rung_limits()
    smallest = make(len(ladder) - 1)
    index = {tag: i for i, tag in enumerate(w_tags)}
    x_index = np.array([[index[(n, "x", i)] for i in range(NX)] for n in range(N + 1)])
    u_index = np.array([[index[(n, "u", i)] for i in range(NU)] for n in range(N)])
    slack_index = np.array([i for i, tag in enumerate(w_tags) if tag[1] == "s"], dtype=int)
    layout = (x_index, u_index, lbg, ubg, risk_shape, slack_index, slots)
    lbx, ubx = variable_bounds(scenario, x_index, u_index, len(w_tags), np.zeros(NX), slack_index)
    pattern = bound_pattern(lbx, ubx, lbg, ubg)
    if settings.time_limit is None:  # uncapped: no call is ever fitted into a time, the priors go unread
        prior = failing = 0.0
    else:
        prior, failing = iteration_times(smallest, scenario, *layout, pattern=pattern)
    cap = math.inf if settings.time_limit is None else USEFUL_RUNG * settings.time_limit
    rungs = [r for r in range(len(ladder) - 1) if ladder[r][1] is not None or ladder[r][0] * failing <= cap]
    solvers = [make(r) for r in rungs] + [smallest]
    limits = tuple(ladder[r] for r in rungs) + (ladder[-1],)

    risk_rows = [i for i, tag in enumerate(g_tags) if tag[1] in ("risk", "budget")]
    corridor_rows = [i for i, tag in enumerate(g_tags) if tag[1] == "corridor"]
    slacks = {tag: j for j, tag in enumerate(tag for tag in w_tags if tag[1] == "s")}
    # the slack of each risk row: its stage's (n, "s", 0), the budget row's (N, "s", 1)
    row_slack = np.array(
        [slacks.get((g_tags[i][0], "s", int(g_tags[i][1] == "budget")), -1) for i in risk_rows], dtype=int
    )
    if not slacks:
        row_slack = np.zeros(0, dtype=int)
    soft_corridor = [slacks[g_tags[i][0], "s", CORRIDOR_SLACK] for i in corridor_rows if slacks]

    def weight(tag: tuple[int, str, int]) -> float:  # a slack's cost over rho: the risk's, the corridor's
        return corridor_weight(N, EARLY_WEIGHT) if tag[2] == CORRIDOR_SLACK else EARLY_WEIGHT ** (N - tag[0])

    return Problem(
        variant=variant,
        solvers=tuple(solvers),
        limits=limits,
        evaluate=ca.Function("evaluate", [nlp["x"], nlp["p"]], [nlp["f"], nlp["g"]]),
        rollout=stages["f"].mapaccum(N),
        beliefs=belief_fn,
        lbg=np.array(lbg),
        ubg=np.array(ubg),
        x_index=x_index,
        u_index=u_index,
        risk_rows=np.array(risk_rows, dtype=int),
        corridor_rows=np.array(corridor_rows, dtype=int),
        row_slack=row_slack,
        slack_index=slack_index,
        slack_costs=np.array([penalty * weight(tag) for tag in w_tags if tag[1] == "s"]),
        w_tags=tuple(w_tags),
        shift_w=np.array([index.get((s + 1, k, c), i) for i, (s, k, c) in enumerate(w_tags)]),
        g_tags=tuple(g_tags),
        build_time=time.perf_counter() - t0,
        jit=jit,
        times=CallTimes(limits, prior, failing),
        acc_index=np.array([i for i, tag in enumerate(w_tags) if tag[1] == "c"], dtype=int),
        acc_rows=np.array([i for i, tag in enumerate(g_tags) if tag[1] == "accumulate"], dtype=int),
        corridor_slack=np.array(soft_corridor, dtype=int),
        pattern=pattern,
    )


def iteration_time(
    solver: ca.Function,
    scenario: Scenario,
    x_index: np.ndarray,
    u_index: np.ndarray,
    lbg: list[float],
    ubg: list[float],
    risk_shape: tuple[int, int],
    slack_index: np.ndarray,
    slots: int = 1,
    repeats: int = 2,
    pattern: BoundPattern | None = None,
) -> float:
    r"""The time of one solver iteration [s] on the scenario's start (its objects in the first
    slots, all active, the rest absent; $\epsilon$; zero risk data) from rest: the fastest of
    ``repeats`` calls (the first also pays one-time set-up).

    The bounds have the steps' ``pattern`` (which entries are fixed, which infinite; the slacks
    $\ge 0$; :class:`agents.mpc.nlp.calls.BoundPatternError` otherwise): CasADi 3.8's fatrop splits the bounds
    into equalities and inequalities at every call, and once a solver was called with another
    split, its later calls ignore ``max_iter`` and run on with fatrop's default options
    (:mod:`agents.mpc.nlp.calls`)."""
    N, n_w = scenario.horizon, solver.size_in("x0")[0]
    x, y, theta = scenario.ego.start.as_tuple()
    x0 = np.array([x, y, theta, float(project(scenario.path, x, y)), *scenario.ego.initial_input])
    measurements = np.zeros((slots, 5))
    active = np.zeros(slots)
    for k, obj in enumerate(scenario.objects[:slots]):
        measurements[k] = (*obj.start.as_tuple(), obj.speed, obj.turn_rate)
        active[k] = 1.0
    rows = risk_shape[0] * slots
    data = np.zeros((N, rows, risk_shape[1] if rows else 0))
    numbers = slot_numbers(scenario, slots)
    p = parameter_vector(scenario.risk_tolerance, scenario.ego.v_ref, measurements, active, numbers, data)
    p = np.concatenate([p, np.zeros(solver.size_in("p")[0] - len(p))])  # risk terms: off
    lbx, ubx = variable_bounds(scenario, x_index, u_index, n_w, x0, slack_index)
    if pattern is not None and bound_pattern(lbx, ubx, lbg, ubg) != pattern:
        raise BoundPatternError("the timing calls' bounds split otherwise than the steps'")
    w0 = np.zeros(n_w)
    w0[x_index] = x0
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        with np.errstate(all="ignore"):
            solver(x0=w0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=p)
        iterations = int(solver.stats().get("iter_count", 0))
        if iterations > 0:
            best = min(best, (time.perf_counter() - t0) / iterations)
    return best if math.isfinite(best) else 1e-3


def iteration_times(
    solver: ca.Function, scenario: Scenario, *layout: Any, pattern: BoundPattern | None = None
) -> tuple[float, float]:
    """The priors of :class:`agents.mpc.nlp.budget.CallTimes`: the time per iteration [s] of ``solver``
    on the scenario's start, and on the same start with a parked object 1 m ahead of the ego,
    inside its boxes at every step (a failing call's, whose line searches evaluate more)."""
    x, y, theta = scenario.ego.start.as_tuple()
    swallowed = scenario.replace(
        object_start=(x + math.cos(theta), y + math.sin(theta), theta), object_speed=0.0, object_turn_rate=0.0
    )
    return (
        iteration_time(solver, scenario, *layout, pattern=pattern),
        iteration_time(solver, swallowed, *layout, pattern=pattern),
    )
