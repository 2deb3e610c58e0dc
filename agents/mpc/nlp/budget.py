"""The real-time bound of an MPC step: a wall-time budget shared by its solver calls, and the choice
of the solver rung (:meth:`agents.mpc.nlp.settings.SolverSettings.rung_limits`) that fits what is left.

IPOPT stops itself at its ``max_wall_time``; fatrop (CasADi 3.8) has no time limit, only
``max_iter``, so its calls are predicted from the measured time per iteration of the same NLP.
``max_iter`` bounds a call only while fatrop keeps its options and each iteration ends; both failed
before (calls of 31 and 1,001 iterations at a limit of 4 that had lost their options; calls that
never returned from one iteration's inertia correction), and :mod:`agents.mpc.nlp.calls` says why and
what keeps them bounded. Every call is recorded (:attr:`agents.SolveReport.calls`); one past its
rung's limit is counted (:attr:`agents.SolveReport.overran_calls`, reported by
``benchmarks.stress``) or, in strict mode, raised.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

WINDOW = 64
"""Calls remembered per NLP variant for the time-per-iteration estimate."""
LONG_CALL = 20
"""Calls of at least this many iterations are also remembered apart: the calls that run into a
rung's limit are long ones, and a failing call's iterations cost more (line searches,
restoration) than a converging one's."""
END_SHARE = 0.1
"""Share of the cap no solver call may use: the step's own work after its last call, and the
error of the calls' predicted times."""
QUANTILE = 90.0
"""The estimate is this percentile of the remembered times per iteration ..."""
SAFETY = 1.3
"""... times this factor (a call's iterations differ in cost: line searches, restoration)."""
UNMEASURED_LONG = 2.0
"""... and a long call's, until a long call of the variant was measured, times this too: the build's
failing probe may price a failing call's iterations low (measured: 1.5 ms against 3.8 ms, the paper's
severity with a budget row; a 140 ms call predicted at 71 ms)."""
SKIP_DISCOUNT = 0.8
"""Factor on the estimate after each call that did not fit (reset by the next measured call) ..."""
SKIP_FLOOR = 1.0 / SAFETY
"""... down to this factor: a discounted estimate is still the measured percentile itself, never
below it. Skips are mostly calls that the step's earlier calls left no time for, not evidence of a
pessimistic estimate; compounded without a floor (0.8^6 = 0.26) they let a 135 ms call be predicted
at 61 ms."""
CALL_OVERHEAD = 5e-4
"""Time [s] a call costs besides its iterations (CasADi's set-up, copying), before any is measured."""
IPOPT_OVERRUN = 2e-3
"""Time [s] an IPOPT call may take beyond its ``max_wall_time`` (it checks once per iteration)."""


class Budget:
    """The time left for the solver calls of one step: ``deadline = start + (1 - END_SHARE) cap``
    [s, ``time.perf_counter``].

    A step that runs inside another (a pilot problem's) gets the outer step's deadline, less the
    outer ``reserve``, when that comes first (:meth:`open`)."""

    def __init__(self, cap: float, start: float | None = None) -> None:
        self.start = time.perf_counter() if start is None else start
        self.cpu_start = time.process_time()
        """The process's CPU time at the start [s, ``time.process_time``]."""
        self.deadline = self.start + (1.0 - END_SHARE) * cap
        """When the step's last solver call must end [s, ``time.perf_counter``]."""
        self.capped = False
        """Whether the budget cut a call short (a smaller rung) or skipped one."""
        self.reserve = 0.0
        """What a step nested in this one must leave [s]."""

    def left(self, reserve: float = 0.0) -> float:
        """Seconds left before the deadline, minus ``reserve`` (kept for later levels)."""
        return self.deadline - time.perf_counter() - reserve

    @classmethod
    @contextmanager
    def open(cls, cap: float) -> Iterator[Budget]:
        """The budget of a step of cap ``cap`` [s], active (for nested steps) inside the block."""
        budget = cls(cap)
        outer = _ACTIVE.get()
        if outer is not None:
            budget.deadline = min(budget.deadline, outer.deadline - outer.reserve)
        token = _ACTIVE.set(budget)
        try:
            yield budget
        finally:
            _ACTIVE.reset(token)


_ACTIVE: ContextVar[Budget | None] = ContextVar("active_budget", default=None)


class CallTimes:
    """The solver calls of one NLP variant: the rungs' limits and the measured wall time per
    iteration of recent calls, shared by every agent that uses the variant in this process."""

    def __init__(self, limits: tuple[tuple[int, float | None], ...], prior: float, failing: float) -> None:
        self.limits = limits
        """``(max_iter, max_wall_time [s] or None)`` of each rung, the largest first."""
        self.prior = prior
        """Time per iteration [s] of a call on the scenario's start, measured at the build."""
        self.failing = failing
        """... and of a failing call (the object inside the boxes), measured at the build."""
        self._all: deque[float] = deque([prior], maxlen=WINDOW)
        self._long: deque[float] = deque([max(prior, failing)], maxlen=WINDOW)
        self._quantiles = (prior, max(prior, failing))
        self._discount = 1.0
        self._long_measured = False

    def record(self, iterations: int, seconds: float) -> None:
        """Remember a call of ``iterations`` iterations that took ``seconds``."""
        if iterations >= 1:
            per_iteration = max(seconds - CALL_OVERHEAD, 0.0) / iterations
            self._all.append(per_iteration)
            if iterations >= LONG_CALL:
                self._long.append(per_iteration)
                self._long_measured = True
            self._quantiles = (_quantile(self._all), _quantile(self._long))
            self._discount = 1.0

    def per_iteration(self, iterations: int = 1) -> float:
        """The conservative time per iteration [s] of a call of up to ``iterations`` iterations:
        :data:`SAFETY` times the :data:`QUANTILE` percentile of the recent calls' (of the recent
        long calls' for a long one, times :data:`UNMEASURED_LONG` before the first)."""
        if iterations < LONG_CALL:
            return self._discount * SAFETY * self._quantiles[0]
        unmeasured = 1.0 if self._long_measured else UNMEASURED_LONG
        return self._discount * SAFETY * unmeasured * self._quantiles[1]

    def predict(self, rung: int) -> float:
        """Upper estimate [s] of a call at ``rung``."""
        iterations, wall = self.limits[rung]
        if wall is not None:
            return wall + IPOPT_OVERRUN
        return CALL_OVERHEAD + iterations * self.per_iteration(iterations)

    def rung(self, available: float) -> int | None:
        """The largest rung whose call fits in ``available`` seconds (None: none fits; then the
        estimate is discounted by :data:`SKIP_DISCOUNT`, down to :data:`SKIP_FLOOR`, until the next
        measured call, so that the safety factor of a pessimistic estimate cannot keep every call
        out for good)."""
        for r in range(len(self.limits)):
            if self.predict(r) <= available:
                return r
        self._discount = max(self._discount * SKIP_DISCOUNT, SKIP_FLOOR)
        return None


def _quantile(history: deque[float]) -> float:
    """The :data:`QUANTILE` percentile of ``history`` (nearest rank; cheaper than numpy's)."""
    ordered = sorted(history)
    return ordered[round(QUANTILE / 100.0 * (len(ordered) - 1))]
