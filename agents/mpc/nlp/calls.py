r"""One solver call of the MPC and what it reports: iterations, time, and the checks that keep a
call bounded.

**Why a call can run unbounded** (CasADi 3.8.2, fatrop 1.1.8), two mechanisms, both checked here:

- *Lost options.* CasADi's fatrop plugin keeps one fatrop solver per memory and sets the options
  (``max_iter``, ``tol``, ``mu_init``, ...) only when it creates one. Each call re-splits the
  bounds into equalities (lb = ub) and inequalities (not both infinite); when a stage's counts
  differ from the cached solver's, the plugin destroys it and creates another *without* setting
  the options (``new_solver`` is computed before the re-split), so every later call runs with
  fatrop's defaults (``max_iter`` 1000, ``tol`` 1e-8, ``mu_init`` 0.1) (CasADi's
  ``FatropInterface::solve`` and ``casadi_fatrop_presolve``, since CasADi's 34a831e "feat solver
  cache"). The bounds of every call of a problem must therefore have the pattern of its build
  (:func:`bound_pattern`); a call with another raises :class:`BoundPatternError` before it runs.
- *An unbounded inertia correction.* Inside one iteration fatrop multiplies its primal
  regularisation $\delta_w$ by 8 to 100 until every pivot $p$ of its Riccati factorisation passes a
  relative test ($p^2 > 10^{-6}$ times the diagonal entry), with no upper limit (IPOPT stops at 1e40
  and fails the call). The regularisation also reaches the inequalities' slacks, so a row (or a
  dynamics row) with gradient $a$ adds $\delta_w a a^T$, and for every $\delta_w$ the relative
  pivots are those of $I + a a^T$, about $1/|a|^2$: once $|a|$ is about a thousand they fail at any
  $\delta_w$, $\delta_w$ overflows, the matrix turns to NaN, and the call never returns, whatever
  ``max_iter``. Traced (gdb on ``blasfeo_dpotrf_l_mn``) on the first call of
  ``SMPC.from_env(RiskCrossing-v0 medium, risk_budget=0.01)`` at seed 20011: the episode budget's
  row had gradients of 1.5e4 (its normaliser $1/B$ = 100 on a risk in J); the stage's pivots failed
  at $\delta_w$ = 0, 1e-4, 1e-2, ..., 1e117 (60 tries, diagonal growing as $\delta_w$ times 4e7) and
  later on NaN; the call never returned (killed after 120 s, and after 300 s in another run). The
  NLP keeps every row's gradient in the risk rows' scale (the budget's terms in units of the
  severity's scale, :mod:`agents.mpc.nlp.risk_budget`) and rejects the budgets and weights that
  would scale it up; :attr:`CallRecord.overran` and the strict mode (:func:`strict_iterations`)
  catch any call that still runs past its rung's limit.

**Strict mode**: a call of more iterations than its rung allows raises
:class:`IterationLimitError` (the tests run strict: ``tests/conftest.py`` sets
:data:`STRICT_ENV`); otherwise it is counted (:attr:`agents.SolveReport.overran_calls`).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any, Protocol

import casadi as ca
import numpy as np

IPOPT_SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
STRICT_ENV = "RISKCROSSING_STRICT_ITERATIONS"
"""Environment variable: ``1`` makes every process strict (:func:`strict`) unless overridden."""
_STRICT: ContextVar[bool | None] = ContextVar("strict_iterations", default=None)


class IterationLimitError(RuntimeError):
    """A solver call ran more iterations than its rung allows (raised in strict mode only)."""


class BoundPatternError(RuntimeError):
    """A call's bounds split into equalities and inequalities otherwise than at the build (CasADi's
    fatrop plugin would drop its options for good)."""


def strict() -> bool:
    """Whether a call past its rung's limit raises: :func:`strict_iterations` if active, else
    :data:`STRICT_ENV`."""
    value = _STRICT.get()
    if value is not None:
        return value
    return os.environ.get(STRICT_ENV, "") not in ("", "0")


@contextmanager
def strict_iterations(on: bool = True) -> Iterator[None]:
    """Within the block, calls past their rung's iteration limit raise (``on``) or are counted."""
    token = _STRICT.set(on)
    try:
        yield
    finally:
        _STRICT.reset(token)


BoundPattern = bytes
"""Which entries of (lbx, lbg) are equalities and which have no bound, as bytes of two masks."""


def bound_pattern(lbx: Any, ubx: Any, lbg: Any, ubg: Any) -> BoundPattern:
    """The split CasADi's fatrop plugin makes of these bounds: equalities (lb = ub), entries
    without a bound (both infinite), inequalities (the rest)."""
    lo = np.concatenate((np.ravel(lbx), np.ravel(lbg)))
    hi = np.concatenate((np.ravel(ubx), np.ravel(ubg)))
    return (lo == hi).tobytes() + ((lo == -np.inf) & (hi == np.inf)).tobytes()


class Solvable(Protocol):
    """What :func:`call_solver` needs of an :class:`agents.mpc.nlp.solver.Problem`."""

    variant: str
    solvers: tuple[ca.Function, ...]
    limits: tuple[tuple[int, float | None], ...]
    pattern: BoundPattern | None


def call_solver(
    problem: Solvable, args: dict[str, Any], solver: str, rung: int = 0
) -> tuple[dict[str, np.ndarray], str, bool, int, dict[str, float]]:
    """One solver call at ``rung``: ``(outputs, status, success, iterations, wall times)``; a
    solver's exception becomes a failed call. Raises :class:`BoundPatternError` (fatrop) before a
    call whose bounds split otherwise than the build's, and in strict mode
    :class:`IterationLimitError` after a call past the rung's iteration limit."""
    if solver == "fatrop" and problem.pattern is not None:
        pattern = bound_pattern(args["lbx"], args["ubx"], args["lbg"], args["ubg"])
        if pattern != problem.pattern:
            raise BoundPatternError(
                f"the bounds of a {problem.variant!r} call split into equalities and inequalities "
                "otherwise than at the build: fatrop would run on without its options"
            )
    function = problem.solvers[rung]
    try:
        with np.errstate(all="ignore"):
            res = function(**args)
        stats = function.stats()
    except Exception as err:  # a solver error is a failed call, never an exception in an episode
        return {}, f"exception: {err}", False, 0, {}
    out = {k: np.asarray(v).ravel() for k, v in res.items()}
    if solver == "ipopt":
        status = str(stats.get("return_status", "unknown"))
        ok = status in IPOPT_SUCCESS
    else:
        status = str(stats.get("unified_return_status", stats.get("return_status", "unknown")))
        ok = bool(stats.get("success", False))
    ok = ok and all(np.all(np.isfinite(out[k])) for k in ("x", "lam_x", "lam_g", "f"))
    times = {k: float(v) for k, v in stats.items() if k.startswith("t_wall_") and v}
    iterations = int(stats.get("iter_count", 0))
    limit = problem.limits[rung][0]
    if iterations > limit + 1 and strict():
        raise IterationLimitError(
            f"a {problem.variant!r} call ran {iterations} iterations at rung {rung}, whose limit is {limit}"
        )
    return out, status, ok, iterations, times
