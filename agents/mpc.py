"""The path-following MPC controller: one step = measure, choose the NLP variant, warm-start,
solve, degrade gracefully; SB3's ``predict`` on top.

The optimal control problem is in :mod:`agents.ocp`, its solver (options, compilation, caches) in
:mod:`agents.solver`, the initial guesses in :mod:`agents.guesses`, the time budget in
:mod:`agents.budget`, the solve attempts in :mod:`agents.attempts`, the last resort in
:mod:`agents.fallback`. The controller adds:

- **Variant choice**: ``"free"`` (no risk rows) when no step's risk can be nonzero anywhere the ego
  can reach within the horizon (distance to the truncation box minus the distance reachable under
  the bounds and rate limits exceeds r_e + r_o + :data:`FREE_MARGIN`), else the agent's risk form.
- **Initial guess**: the previous solution shifted by one stage (inputs shifted, the last repeated,
  states re-simulated from the measurement) with its shifted multipliers. The first solve of an
  episode solves from each of a few rollouts (brake, track the path, reverse) and keeps the plan of
  least cost; a subclass may instead hand it the plan of a cheaper pilot problem
  (:meth:`PathFollowingMPC._pilot_plan`, the Monte Carlo SMPC's 100-draw pilot), which did that.
- **Graceful degradation** in a fixed order, within a wall-time cap (see :class:`PathFollowingMPC`).
"""

from __future__ import annotations

import functools
import gc
import math
import os
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from agents.base import SolveReport, as_batch
from agents.budget import Budget
from agents.calls import CallRecord, call_solver
from agents.objects import check_slots, combine, slot_scenario
from agents.ocp import STAGE_COSTS, problem_key, slot_numbers, soft_variant
from agents.solver import (
    DEFAULT_JIT_CACHE,
    SOLVERS,
    Problem,
    SolverSettings,
    build_problem,
    cached_problem,
)
from agents.step import FEASIBLE_SLACK, MANOEUVRE_TIME, SOFT_SHARE, Step
from risk_env import observation as ob
from risk_env.ops import NUMPY
from risk_env.path import point
from risk_env.prediction import Belief
from risk_env.risk import RiskEstimator, WorstCaseRisk, signed_box_distance
from risk_env.scenario import Scenario

__all__ = ["FEASIBLE_SLACK", "FREE_MARGIN", "SOFT_SHARE", "SOLVERS", "STAGE_COSTS", "PathFollowingMPC"]

FREE_MARGIN = 0.5
"""Extra distance [m] the reachable set must keep from every box for the ``"free"`` variant."""
RT_SHARE = 0.2
"""The default wall-time cap of a step, as a share of the sample time T."""
RUNGS = 6
"""Rungs of the solver ladder per NLP variant: 1, 1/2, ..., 1/32 of the iteration (fatrop: 150 down
to 4 by default) or time (IPOPT) limit."""
SOFT_PENALTY = 1e4
"""Default rho of the soft problem's exact L1 penalty [cost per margin unit]."""


class PathFollowingMPC:
    """Path-following MPC with a risk constraint; the subclasses say which (:class:`agents.RMPC`,
    :class:`agents.SMPC`). The problem is in :mod:`agents.ocp`, its solver in :mod:`agents.solver`.

    Graceful degradation, in this order, each step (never raising inside an episode, never
    returning NaN; :attr:`last_solve` says which level acted, :attr:`failures` counts the steps
    where (b) or (c) did):

    (a) the hard problem: warm-started from the shifted previous plan (an episode's first step:
        from each of the best initial-guess rollouts, up to ``cold_starts``, keeping the plan of
        least cost). A success is IPOPT's "Solve_Succeeded" or "Solved_To_Acceptable_Level",
        fatrop's success flag, with finite numbers.
    (b) if none converges (infeasible, iteration or time limit, NaN, an exception): the same
        problem with its risk rows softened by L1-penalised slacks (the ``"*_soft"`` variants of
        :mod:`agents.ocp`), from the shifted plan, then the best rollouts and manoeuvres (up to
        ``cold_starts``; they replace the hard problem's cold retries). The penalty is
        exact: where the hard problem is feasible (and rho exceeds its risk rows' multipliers) the
        soft problem's solution is the hard one's, with zero slacks. So a soft plan whose slacks
        vanish (to :data:`FEASIBLE_SLACK`) solves the hard problem, and is level (a)
        (``fallback=None``, ``retried=True``, ``variant="*_soft"``). Otherwise the soft plan, the
        least violation of the risk bound the solver found (so the most clearance it could keep),
        is applied: ``fallback="soft"`` with the ``violation``.
        After a step whose soft plan missed the risk bound the next step goes to the soft problem
        directly, from the shifted plan only ("elastic mode", as in SNOPT): the hard problem is
        most likely infeasible still, and where it is not, its exact penalty returns its solution.
    (c) if that fails too: the safest of a family of rate-limited manoeuvres (brake, hold,
        accelerate, reverse, each straight or turning fully left or right; :mod:`agents.fallback`),
        judged by the agent's own risk and the worst-case clearance over the horizon:
        ``fallback="manoeuvre"``.

    **Real-time bound**: a step takes at most ``max_solve_time`` of wall time (by default 20 % of the
    sample time), enforced through the solver's own limits: each NLP is built at a few rungs of
    iteration limits (fatrop: ``max_iter / 2**r``) or wall-time limits (IPOPT: ``max_wall_time =
    max_solve_time / 2**r``), and each call runs at the largest rung that fits the time left,
    judged from the measured time per iteration (:mod:`agents.budget`). The hard problem's calls
    leave :data:`SOFT_SHARE` of the cap to the soft problem, which leaves the manoeuvres their
    (small, measured) time. When no rung fits, the next level acts.

    Args:
        scenario: the case study; its ``risk_tolerance`` is epsilon unless overridden.
        risk_tolerance: epsilon [units of the severity], >= 0; overrides the scenario's.
        solver: one of :data:`SOLVERS`.
        stage_cost: one of :data:`STAGE_COSTS` (see :mod:`agents.ocp`).
        jit: run the solver on compiled code (see "Compiled solvers" in :mod:`agents.solver`); falls
            back to the uncompiled solver (with a warning) when no C compiler exists or code
            generation, compilation or loading fails. Off by default: the first build compiles
            (the exact SMPC's three variants, shared by every uncertainty level and tolerance, in
            about 40 s at -O1 on the project's machine; see :attr:`build_time`), later builds load
            the cached library in well under a second; the evaluations then run about twice as
            fast.
        jit_opt: the C compiler's optimisation level (``-O1`` runs as fast as ``-O3`` here and
            compiles in about 60 % of its time; ``-O0`` is no faster than uncompiled).
        jit_cache: directory where compiled solvers (shared libraries) are kept and reused by later
            processes; ``None``: a per-process temporary directory. Default:
            ``$RISKMPC_JIT_CACHE`` or ``~/.cache/riskcrossing/jit``.
        tol, max_iter: solver tolerance and iteration limit.
        warm_start: start from the shifted previous solution (IPOPT: with its multipliers).
        backoff: the risk rows ask ``margin_n >= backoff`` (margin units: metres of clearance, or
            risk over the severity's scale), so a converged plan stays a hair off the boundary where
            the worst-case risk's hard indicator jumps, and float32 observations cannot put the
            applied step on its wrong side.
        cold_starts: how many initial-guess rollouts (best first) a level may try from cold: the
            first step of an episode solves the hard problem from each of them and keeps the plan
            of least cost (the problem is not convex: going round the object on either side,
            waiting or reversing are separate local optima); the soft problem tries them after
            the shifted plan.
        max_solve_time: the wall-time cap of one step [s] (None: 20 % of the sample time;
            ``math.inf``: no cap, one solver per NLP).
        soft_penalty: rho of the soft problem's penalty ``rho * sum_n s_n`` [cost per margin unit];
            it must exceed the risk rows' multipliers for the penalty to be exact.
        solver_options: extra nlpsol options; ``{"ipopt": {...}}`` / ``{"fatrop": {...}}`` update
            the plugin's own options.
        seed: seed of the agent's generator (Monte Carlo draws).
        object_slots: K, the object slots of the observations it reads (None: the scenario's
            number of objects; match the env's ``object_slots``). One solver with K slots plans
            against every present object (:mod:`agents.objects`); slot k takes object k's radius,
            mass and uncertainty, slots beyond the scenario's objects the last object's. An
            observation with another slot count raises ``ValueError`` naming both.
    """

    risk_method: str = ""
    RISK_METHODS: ClassVar[tuple[str, ...]] = ()
    ZERO_TOLERANCE_VARIANT: ClassVar[bool] = False
    """Whether the subclass has an exact, cheaper form at epsilon = 0 (``_margin(..., zero=True)``)."""

    def __init__(
        self,
        scenario: Scenario,
        *,
        risk_tolerance: float | None = None,
        solver: str = "fatrop",
        stage_cost: str = "reached",
        jit: bool = False,
        jit_opt: int = 1,
        jit_cache: str | os.PathLike[str] | None = DEFAULT_JIT_CACHE,
        tol: float = 1e-4,
        max_iter: int = 150,
        warm_start: bool = True,
        backoff: float = 1e-3,
        cold_starts: int = 3,
        solver_options: dict[str, Any] | None = None,
        seed: int | None = 0,
        max_solve_time: float | None = None,
        soft_penalty: float = SOFT_PENALTY,
        object_slots: int | None = None,
    ) -> None:
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a risk_env Scenario, got {type(scenario).__name__}")
        if not (isinstance(backoff, (int, float)) and backoff >= 0):
            raise ValueError(f"backoff must be >= 0, got {backoff!r}")
        if isinstance(cold_starts, bool) or not isinstance(cold_starts, int) or cold_starts < 1:
            raise ValueError(f"cold_starts must be an integer >= 1, got {cold_starts!r}")
        cap = RT_SHARE * scenario.dt if max_solve_time is None else max_solve_time
        if isinstance(cap, bool) or not isinstance(cap, (int, float)) or not cap > 0:
            raise ValueError(f"max_solve_time must be a time > 0 [s] (or None), got {max_solve_time!r}")
        self.max_solve_time = float(cap)
        """The wall-time cap of one step [s]."""
        self.scenario = scenario
        self.slots = check_slots(object_slots, scenario)
        """K, the object slots (fixed at construction)."""
        self._numbers = slot_numbers(scenario, self.slots)
        slot_scenarios = [slot_scenario(scenario, k) for k in range(self.slots)]
        self.estimators: tuple[RiskEstimator, ...] = tuple(self._estimator(s) for s in slot_scenarios)
        """Each slot's risk estimator (its radius, mass and uncertainty)."""
        self.estimator = self.estimators[0]
        self._worsts = tuple(WorstCaseRisk(s) for s in slot_scenarios)
        self.risk_tolerance = scenario.risk_tolerance if risk_tolerance is None else risk_tolerance
        self.settings = SolverSettings(
            solver=solver,
            stage_cost=stage_cost,
            jit=bool(jit),
            jit_opt=int(jit_opt),
            jit_cache=jit_cache,
            tol=tol,
            max_iter=max_iter,
            warm_start=bool(warm_start),
            solver_options=dict(solver_options or {}),
            time_limit=self.max_solve_time if math.isfinite(self.max_solve_time) else None,
            rungs=RUNGS if math.isfinite(self.max_solve_time) else 1,
            soft_penalty=soft_penalty,
        )
        """How the NLP is solved (:class:`agents.solver.SolverSettings`)."""
        self.backoff = float(backoff)
        self.cold_starts = cold_starts
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.failures = 0
        self.last_solve: SolveReport | None = None
        self.last_solves: list[SolveReport] = []
        self._memory: dict[int, dict[str, Any]] = {}
        self._problems: dict[str, Problem] = {}
        self._maps: dict[tuple[str, str, str], np.ndarray] = {}
        self._manoeuvre_time = MANOEUVRE_TIME
        ego, dt = scenario.ego, scenario.dt
        self._speed_cap = max(abs(ego.v_min), abs(ego.v_max))
        self._dv = ego.accel_max * dt
        variant = self._risk_variant()
        built = [self._problem(v) for v in ("free", variant, soft_variant(variant))]
        self.build_time = sum(p.build_time for p in built)
        """Seconds spent building (with jit: compiling) the solvers at construction; 0 when they came
        from the process-wide cache."""

    # ------------------------------------------------------------------ public API
    @property
    def risk_tolerance(self) -> float:
        """epsilon [units of the severity]; a solver parameter, so it may change between steps."""
        return self._epsilon

    @risk_tolerance.setter
    def risk_tolerance(self, value: float) -> None:
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"risk_tolerance must be a number >= 0, got {value!r}") from None
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"risk_tolerance must be a finite number >= 0, got {value!r}")
        self._epsilon = value

    @property
    def horizon(self) -> int:
        return self.scenario.horizon

    @property
    def compiled(self) -> bool:
        """Whether the solver in use runs jit-compiled functions."""
        return self._problem(self._risk_variant()).jit

    @classmethod
    def from_env(cls, env: Any, **kwargs: Any) -> PathFollowingMPC:
        """An agent for ``env.unwrapped.scenario`` (the env's scenario only, never its state)."""
        scenario = getattr(getattr(env, "unwrapped", env), "scenario", None)
        if not isinstance(scenario, Scenario):
            raise TypeError("env.unwrapped.scenario is not a risk_env Scenario")
        return cls(scenario, **kwargs)

    def reset(self, seed: int | None = None) -> None:
        """Forget warm starts and plans, zero :attr:`failures`, re-seed the generator (with ``seed``
        or the constructor's)."""
        self._memory.clear()
        self.failures = 0
        self.last_solve = None
        self.last_solves = []
        self.rng = np.random.default_rng(self.seed if seed is None else seed)

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, None]:
        """SB3's predictor protocol: float32 action(s) (v [m/s], omega [rad/s]) and no state.

        ``observation``: one ``(10 + 6 K,)`` (K: :attr:`slots`) or a batch ``(B, 10 + 6 K)``,
        each solved in turn with its own warm start (by batch index); the plan respects every
        present object's risk bound (an observation with another slot count:
        ``ValueError``). ``episode_start`` (bool or ``(B,)``) drops the warm start;
        so does a new episode detected from the observation (its last applied input is not the
        action returned, or the ego is over 1 m from where the plan put it).
        """
        obs, single = as_batch(observation, ob.size(self.slots))
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
                self._memory.pop(i, None)
            report = self._step(i, o)
            actions[i] = report.action
            reports.append(report)
        self.last_solves = reports
        self.last_solve = reports[-1]
        return (actions[0] if single else actions), None

    # ------------------------------------------------------------------ subclass hooks
    def _estimator_key(self) -> tuple[Any, ...]:
        """What, besides the scenario and the solver settings, changes the built problem."""
        raise NotImplementedError

    def _estimator(self, scenario: Scenario) -> RiskEstimator:
        """The agent's estimator for one slot's single-object ``scenario``."""
        raise NotImplementedError

    def _risk_parameter_shape(self) -> tuple[int, int]:
        """Shape of the per-step risk data parameter ((0, 0): none)."""
        return (0, 0)

    def _margin(
        self, ego: ca.SX, beliefs: list[Belief], epsilon: ca.SX, data: ca.SX, numbers: ca.SX, zero: bool
    ) -> ca.SX:
        """Symbolic rows of one stage (:data:`agents.ocp.Margin`), each >= 0 iff the risk bound
        holds at this step for every active slot; ``zero``: the form for epsilon = 0 (only with
        :attr:`ZERO_TOLERANCE_VARIANT`)."""
        raise NotImplementedError

    def _pilot_plan(
        self, index: int, obs_vec: np.ndarray, variant: str
    ) -> tuple[np.ndarray, int, tuple[CallRecord, ...]] | None:
        """A cold start's first initial guess: inputs ``(N, NU)`` planned on a cheaper problem, the
        solver iterations that took and its calls; None: start from the rollouts."""
        return None

    def _risk_data(self, futures: list[Belief | None]) -> np.ndarray:
        """Per-step risk data ``(N, K J, 3)`` for one solve, the slots' blocks stacked (Monte
        Carlo: fresh draws for the present slots, zeros for the absent ones)."""
        return np.zeros((self.horizon, 0, 0))

    def _slot_risk(self, slot: int, ego: np.ndarray, belief: Belief, data: np.ndarray) -> np.ndarray:
        """Slot ``slot``'s risk ``(N,)`` of ego states ``(N, 4)`` against its beliefs at n = 1..N
        (``data``: its block ``(N, J, 3)``)."""
        raise NotImplementedError

    def _risk_numpy(self, ego: np.ndarray, futures: list[Belief | None], data: np.ndarray) -> np.ndarray:
        """Risk ``(N,)`` of ego states ``(N, 4)``: the sum over the present slots (``futures[k]``
        not None) of their risks at n = 1..N; zeros when no object is present."""
        rows = data.shape[1] // self.slots if data.size else 0
        terms = [
            self._slot_risk(k, ego, f, data[:, k * rows : (k + 1) * rows])
            for k, f in enumerate(futures)
            if f is not None
        ]
        return combine(terms) if terms else np.zeros(np.shape(ego)[:-1])

    def _risk_terms(self) -> tuple[bool, bool]:
        """``(budget, weight)``: whether the NLP carries the episode risk budget and the weighted
        risk in its objective (:mod:`agents.risk_budget`); neither by default."""
        return (False, False)

    def _risk_value(self, ego: ca.SX, beliefs: list[Belief], data: ca.SX, numbers: ca.SX) -> ca.SX:
        """Symbolic R of one stage, the budget's and the cost's (with :meth:`_risk_terms`): the
        sum over the active slots (:data:`agents.ocp.RiskValue`)."""
        raise NotImplementedError

    def _terms_parameters(self, index: int, new_episode: bool) -> np.ndarray:
        """The risk terms' solver parameters (:data:`agents.ocp.TERMS`) of batch entry ``index``
        (empty without terms); ``new_episode``: its memory was dropped."""
        return np.zeros(0)

    # ------------------------------------------------------------------ building
    def _risk_variant(self) -> str:
        return "zero" if self.ZERO_TOLERANCE_VARIANT and self._epsilon <= 0.0 else "general"

    def _problem(self, variant: str) -> Problem:
        if variant not in self._problems:
            key = (
                type(self).__name__,
                variant,
                problem_key(self.scenario),  # not epsilon, v_ref, the uncertainty, objects: parameters
                self.slots,
                self._estimator_key(),  # also for "free": the parameter layout (e.g. draws) differs
                self.settings.key(),
                self._risk_terms(),
            )
            build = functools.partial(
                build_problem,
                self.scenario,
                variant,
                self.settings,
                self._margin,
                self._risk_parameter_shape(),
                self._risk_value if any(self._risk_terms()) else None,
                self._risk_terms(),
                self.slots,
            )
            self._problems[variant] = cached_problem(key, build)
        return self._problems[variant]

    # ------------------------------------------------------------------ one step
    def _measured_state(self, o: ob.Observation) -> np.ndarray:
        """x_0: the pose with theta unwrapped near theta_P(lambda_k), lambda_k, the last input."""
        lam = o.progress
        theta_p = float(point(self.scenario.path, lam)[2])
        theta = theta_p + float(NUMPY.wrap_angle(o.ego_pose[2] - theta_p))
        return np.array([o.ego_pose[0], o.ego_pose[1], theta, lam, o.ego_input[0], o.ego_input[1]])

    def _reach(self, v_last: float) -> np.ndarray:
        """Upper bound [m] on the distance from the current position to the state n = 1..N."""
        speeds = np.minimum(self._speed_cap, abs(v_last) + self._dv * np.arange(1, self.horizon + 1))
        return np.cumsum(speeds) * self.scenario.dt

    def _risk_possible(self, x0: np.ndarray, future: Belief, slot: int = 0) -> bool:
        """Whether some step's risk of slot ``slot``'s object could be nonzero where the ego can
        reach (else the slot is inactive; no active slot: ``"free"``)."""
        distance = signed_box_distance(x0[0] - future.x, x0[1] - future.y, future.half_x, future.half_y)
        spare = distance - self._reach(x0[4]) - float(self._numbers[slot, 0])
        return bool(np.any(spare <= FREE_MARGIN))

    def _call(
        self, pr: Problem, args: dict[str, Any], rung: int = 0
    ) -> tuple[dict[str, np.ndarray], str, bool, int, dict]:
        """One solver call (:func:`agents.calls.call_solver`); a method so tests can watch it."""
        return call_solver(pr, args, self.settings.solver, rung)

    def _step(self, index: int, obs_vec: np.ndarray) -> SolveReport:
        """One step for the observation ``obs_vec`` (10 + 6 K,) of batch entry ``index``
        (:class:`agents.step.Step`), within the wall-time cap."""
        collecting = gc.isenabled()
        gc.disable()  # no garbage-collection pause inside the step: it runs between steps
        try:
            with Budget.open(self.max_solve_time) as budget:
                return Step(self, index, obs_vec, budget).run()
        finally:
            if collecting:
                gc.enable()

    def _new_episode(self, mem: dict[str, Any], o: ob.Observation) -> bool:
        """The observation does not continue the episode this memory belongs to."""
        if "action" not in mem or np.max(np.abs(o.ego_input - mem["action"])) > 1e-3:
            return True
        return bool(np.hypot(*(o.ego_pose[:2] - mem["predicted"])) > 1.0)
