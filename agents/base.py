"""The seam between controllers and the rest: the Policy protocol and the per-step solve report.

Every agent (MPC or learned) offers stable-baselines3's predictor protocol,
``action, state = agent.predict(obs, state=None, episode_start=None, deterministic=True)``, so
SB3's ``evaluate_policy`` and the project's benchmarks drive them alike.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from risk_env import checks
from risk_env import observation as ob

FALLBACK_KINDS: tuple[str, ...] = ("soft", "manoeuvre")
"""The MPC's fallback levels, in order, when the hard problem gives no plan: ``"soft"`` (the plan of
the same problem with its risk rows softened by L1-penalised slacks) and ``"manoeuvre"`` (the safest
of a family of rate-limited manoeuvres, judged by the agent's own risk and worst-case clearance)."""


@runtime_checkable
class Policy(Protocol):
    """Anything with SB3's ``predict``: one observation ``(10 + 6 K,)`` -> action ``(2,)``, or a
    batch ``(B, 10 + 6 K)`` -> ``(B, 2)`` (:mod:`risk_env.observation`); ``state`` is the recurrent
    state (``None`` for MPC agents)."""

    def predict(
        self,
        observation: np.ndarray,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]: ...


@dataclass(frozen=True)
class CallRecord:
    """What one solver call did."""

    variant: str
    """The NLP variant called (``"general"``, ``"zero_soft"``, ...)."""
    rung: int
    """Its rung (0: the largest)."""
    limit: int
    """The rung's ``max_iter``."""
    iterations: int
    """Iterations the solver reported."""
    wall_time: float
    """Wall time of the call [s]."""
    cpu_time: float
    """CPU time of the process during the call [s]."""
    status: str
    """The solver's return status."""
    success: bool
    """The call converged."""

    @property
    def overran(self) -> bool:
        """More iterations than the rung allows (fatrop counts one beyond its ``max_iter``)."""
        return self.iterations > self.limit + 1


@dataclass
class SolveReport:
    """What one MPC step did. Arrays use the prediction index n = 0..N (states) or n = 0..N-1
    (inputs); ``risk[n - 1]`` belongs to the predicted state n."""

    solve_time: float
    """Wall time of the whole step [s]: observation, initial guess, solver call(s), fallback."""
    success: bool
    """The plan applied came from a converged solve of the hard or the soft problem (IPOPT's
    "Solved To Acceptable Level" counts)."""
    status: str
    """The solver's return status of the last call (e.g. ``"Solve_Succeeded"``)."""
    iterations: int
    """Solver iterations, summed over the calls of this step."""
    fallback: str | None
    """``None`` when the hard problem's plan was applied, else the level of :data:`FALLBACK_KINDS`
    that acted."""
    action: np.ndarray
    """The input applied ``(2,)``: v [m/s], omega [rad/s]."""
    ego_trajectory: np.ndarray
    """Predicted ego poses ``(N+1, 3)``: c1 [m], c2 [m], theta [rad] (unwrapped near the path)."""
    inputs: np.ndarray
    """Planned inputs ``(N, 2)``: v [m/s], omega [rad/s]."""
    path_speed: np.ndarray
    """Planned path speed u2 ``(N,)`` [m/s] of the timing law."""
    lambdas: np.ndarray
    """Planned path parameter ``(N+1,)`` [m], lambda_0 = the measured closest point."""
    risk_tolerance: float
    """epsilon used in this solve [units of the severity]."""
    cost: float = float("nan")
    """Objective value of the plan."""
    retried: bool = False
    """A first (warm-started) call failed and a cold start from the initial-guess candidates ran."""
    variant: str = ""
    """Which built NLP ran: ``"general"``, ``"zero"`` (epsilon = 0 form) or ``"free"`` (no risk
    row could bind: the object's boxes are out of the ego's reach over the horizon)."""
    solver_time: float = 0.0
    """Wall time inside the solver call(s) [s]."""
    timings: dict[str, float] = field(default_factory=dict)
    """Solver-internal wall times [s] (``t_wall_*`` of nlpsol's stats) of the last call."""
    violation: float = 0.0
    """``"soft"``: the largest slack, max_n s_n, by which the plan's risk rows miss ``margin_n >=
    backoff`` [margin units: metres of clearance, or risk over the severity's scale]; 0 otherwise."""
    manoeuvre: str = ""
    """``"manoeuvre"``: the name of the manoeuvre applied (e.g. ``"reverse_left"``)."""
    failed_calls: int = 0
    """Solver calls of this step that did not converge (every attempt, every level)."""
    cpu_time: float = 0.0
    """CPU time of the process during the step [s]: the step's own work, which :attr:`solve_time`
    exceeds when other processes took the CPU."""
    overran_calls: int = 0
    """Solver calls that ran past their rung's iteration limit (fatrop may ignore ``max_iter``, see
    :mod:`agents.mpc.nlp.budget`): the calls the time cap could not bound."""
    capped: bool = False
    """The step's time cap (``max_solve_time``) cut a solver call short (it failed at a smaller
    rung's iteration or time limit) or left no time for one."""
    calls: tuple[CallRecord, ...] = ()
    """Every solver call of the step, in order: its variant, rung, iteration limit, iterations,
    wall and CPU time, status (:class:`CallRecord`)."""
    risk_fn: Callable[[], np.ndarray] | None = field(default=None, repr=False, compare=False)
    """Computes :attr:`risk` on first access (a diagnostic: the step does not wait for it)."""
    _risk: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def risk(self) -> np.ndarray:
        r"""Predicted risk ``(N,)`` at the states $n = 1, \dots, N$ with speed $v_{n-1}$, re-evaluated by the
        numpy estimator that the constraint uses (Monte Carlo: the same draws, hard indicator).
        Computed on first access, outside :attr:`solve_time`."""
        if self._risk is None:
            self._risk = np.asarray(self.risk_fn(), dtype=float).reshape(-1) if self.risk_fn else np.zeros(0)
        return self._risk

    @property
    def failed(self) -> bool:
        return self.fallback is not None

    @property
    def max_risk(self) -> float:
        return float(np.max(self.risk)) if self.risk.size else 0.0


def as_batch(observation: Any, size: int) -> tuple[np.ndarray, bool]:
    """``(B, size)`` float64 observations (B >= 1) and whether the input was a single ``(size,)``
    one; raises ``ValueError`` naming the value for anything else (an empty batch, bools,
    strings, complex numbers, a wrong shape)."""
    expected = f"an observation ({size},) or a batch (B, {size}) of real numbers"
    obs = checks.real_array(observation, "observation", expected)
    if obs.ndim not in (1, 2) or obs.shape[-1] != size:
        raise ValueError(
            f"observation must have shape ({size},) or (B, {size}), got {obs.shape}{_slots_hint(obs, size)}"
        )
    if obs.ndim == 1:
        return obs[None, :], True
    if obs.shape[0] == 0:
        raise ValueError(
            f"observation is an empty batch, shape {obs.shape}; pass at least one observation ({size},)"
        )
    return obs, False


def _slots_hint(obs: np.ndarray, size: int) -> str:
    """Why a RiskCrossing-v0 observation has the wrong length: its object slots differ."""
    try:
        found, wanted = ob.slot_count(obs.shape[-1]), ob.slot_count(size)
    except (ValueError, IndexError):
        return ""
    return f" (an observation with {found} object slot(s); this agent reads {wanted})"


def predict_each(
    observation: Any,
    size: int,
    episode_start: Any,
    forget: Callable[[int], None],
    step: Callable[[int, np.ndarray], Any],
) -> tuple[np.ndarray, list[Any]]:
    """SB3's ``predict`` for a policy that acts on one observation at a time: ``(actions, reports)``
    with float32 actions ``(2,)`` for one observation ``(size,)`` or ``(B, 2)`` for a batch
    ``(B, size)``. Entry i is ``step(i, obs_i)`` (a report with an ``action``); ``forget(i)`` first
    where ``episode_start`` (a bool or ``(B,)``) says a new episode starts."""
    obs, single = as_batch(observation, size)
    starts = np.zeros(len(obs), dtype=bool)
    if episode_start is not None:
        flags = np.asarray(episode_start, dtype=bool).reshape(-1)
        if flags.size not in (1, len(obs)):
            raise ValueError(
                f"episode_start must have 1 or {len(obs)} entries (one per observation), got {flags.size}"
            )
        starts |= np.broadcast_to(flags, (len(obs),))
    actions = np.empty((len(obs), 2), dtype=np.float32)
    reports = []
    for i, o in enumerate(obs):
        if starts[i]:
            forget(i)
        report = step(i, o)
        actions[i] = report.action
        reports.append(report)
    return (actions[0] if single else actions), reports
