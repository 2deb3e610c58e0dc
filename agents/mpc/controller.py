"""The path-following MPC controller (:class:`PathFollowingMPC`): SB3's ``predict`` over a step
that measures (:mod:`agents.mpc.measure`), chooses the NLP variant (``"free"``: no risk rows, when
no object can matter within the horizon) and runs the step pipeline (:mod:`agents.mpc.step`: warm
start, solve, degrade gracefully within a wall-time cap) on the NLP of :mod:`agents.mpc.nlp`."""

from __future__ import annotations

import functools
import gc
import math
import os
from typing import Any, ClassVar

import numpy as np

from agents.base import SolveReport, predict_each
from agents.mpc import measure
from agents.mpc.hooks import RiskForm
from agents.mpc.measure import FREE_MARGIN
from agents.mpc.nlp.budget import Budget
from agents.mpc.nlp.calls import call_solver
from agents.mpc.nlp.compiled import DEFAULT_JIT_CACHE
from agents.mpc.nlp.ocp import STAGE_COSTS, problem_key, soft_variant
from agents.mpc.nlp.parameters import parameter_vector
from agents.mpc.nlp.settings import SOLVERS, SolverSettings
from agents.mpc.nlp.solver import Problem, build_problem, cached_problem
from agents.mpc.objects import MODE_THRESHOLD, Slots, check_slots, check_threshold, combine
from agents.mpc.step import FEASIBLE_SLACK, MANOEUVRE_TIME, SOFT_SHARE, Step, StepContext, StepInput
from risk_env import checks
from risk_env import observation as ob
from risk_env.prediction.belief import Belief
from risk_env.prediction.predictors import Predictor, make_predictor
from risk_env.risk.estimators import RiskEstimator, WorstCaseRisk, with_bodies
from risk_env.scenario.scenario import Scenario

__all__ = ["FEASIBLE_SLACK", "FREE_MARGIN", "SOFT_SHARE", "SOLVERS", "STAGE_COSTS", "PathFollowingMPC"]

RT_SHARE = 0.2
"""The default wall-time cap of a step, as a share of the sample time T."""
RUNGS = 6
"""Rungs of the solver ladder per NLP variant: 1, 1/2, ..., 1/32 of the iteration (fatrop: 150 down
to 4 by default) or time (IPOPT) limit."""
SOFT_PENALTY = 1e4
r"""Default $\rho$ of the soft problem's exact L1 penalty [cost per margin unit]."""


class PathFollowingMPC(RiskForm):
    r"""Path-following MPC with a risk constraint; the subclasses say which (:class:`agents.RMPC`,
    :class:`agents.SMPC`). The problem is in :mod:`agents.mpc.nlp.ocp`, its solver in
    :mod:`agents.mpc.nlp.solver`.

    Each step degrades gracefully in a fixed order, (a) the hard problem, (b) the same problem with
    softened risk rows, (c) the safest rate-limited manoeuvre, within a wall-time cap of
    ``max_solve_time`` (:mod:`agents.mpc.step`); it never raises inside an episode and never
    returns NaN. :attr:`last_solve` says which level acted, :attr:`failures` counts the steps
    where (b) or (c) did.

    Args:
        scenario: the case study; its ``risk_tolerance`` is $\epsilon$ unless overridden.
        risk_tolerance: $\epsilon$ [units of the severity], $\ge 0$; overrides the scenario's.
        solver: one of :data:`SOLVERS`.
        stage_cost: one of :data:`STAGE_COSTS` (see :mod:`agents.mpc.nlp.ocp`).
        jit: run the solver on compiled code ("Compiled solvers" in :mod:`agents.mpc.nlp.solver`); falls
            back to the uncompiled solver (with a warning) when compiling or loading fails. Off by
            default: the first build compiles (:attr:`build_time`), later ones load the cached library.
        jit_opt: the C compiler's optimisation level (``-O1``: as fast as ``-O3``, compiled sooner).
        jit_cache: directory where compiled solvers (shared libraries) are kept and reused by later
            processes; ``None``: a per-process temporary directory. Default:
            ``$RISKMPC_JIT_CACHE`` or ``~/.cache/riskcrossing/jit``.
        tol, max_iter: solver tolerance and iteration limit.
        warm_start: start from the shifted previous solution (IPOPT: with its multipliers).
        restart_standing: where the ego and its last plan stand, also solve from cold (keep the cheaper).
        backoff: the risk rows ask $\mathrm{margin}_n \ge \mathrm{backoff}$ (margin units: metres of
            clearance, or risk over the severity's scale), so a converged plan stays a hair off the
            boundary where the worst-case risk's hard indicator jumps, and float32 observations
            cannot put the applied step on its wrong side.
        cold_starts: how many initial-guess rollouts (best first) a level may try from cold; the
            first step keeps the cheapest plan (going round either side, waiting or reversing are
            separate local optima); the soft problem tries them after the shifted plan.
        max_solve_time: the wall-time cap of one step [s] (None: 20 % of the sample time;
            ``math.inf``: no cap, one solver per NLP).
        soft_penalty: $\rho$ of the soft problem's penalty $\rho \sum_n s_n$ [cost per margin unit];
            it must exceed the risk rows' multipliers for the penalty to be exact.
        solver_options: extra nlpsol options; ``{"ipopt": {...}}`` / ``{"fatrop": {...}}`` update
            the plugin's own options.
        seed: seed of the agent's generator (Monte Carlo draws).
        object_slots: $K$, the object slots of the observations it reads (None: the scenario's
            number of objects; match the env's ``object_slots``). One solver with $K$ slots plans
            against every present object (:mod:`agents.mpc.objects`); slot $k$ takes object $k$'s radius,
            mass and uncertainty, slots beyond the scenario's objects the last object's. An
            observation with another slot count raises ``ValueError`` naming both.
        predictor: the objects' prediction: ``None`` or ``"constant"`` (the paper's, made inside the
            NLP from each slot's measurement) or any :class:`risk_env.prediction.Predictor`,
            whose modes (likeliest first) fill ``modes`` rows per object slot as solver
            parameters: one built solver serves every scene (:class:`agents.mpc.objects.Slots`).
        modes: $M$, the mode slots per object (default 3 with a predictor, 1 without).
        mode_threshold: $w_{min}$ in $[0, 1]$: the RMPC plans against every mode of at least this weight
            (the likeliest alone when none is); the SMPC against all, each weighted.
    """

    risk_method: str = ""
    RISK_METHODS: ClassVar[tuple[str, ...]] = ()
    WEIGHTED: ClassVar[bool] = False
    """Whether the risk is an expectation, summed over a mixture's modes with their weights (the
    SMPC); else every mode of weight at least ``mode_threshold`` is a row of its own (the RMPC)."""
    ZERO_TOLERANCE_VARIANT: ClassVar[bool] = False
    r"""Whether the subclass has an exact, cheaper form at $\epsilon = 0$ (``_margin(..., zero=True)``)."""

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
        restart_standing: bool = False,
        backoff: float = 1e-3,
        cold_starts: int = 3,
        solver_options: dict[str, Any] | None = None,
        seed: int | None = 0,
        max_solve_time: float | None = None,
        soft_penalty: float = SOFT_PENALTY,
        object_slots: int | None = None,
        predictor: str | Predictor | None = None,
        modes: int | None = None,
        mode_threshold: float = MODE_THRESHOLD,
    ) -> None:
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a risk_env Scenario, got {type(scenario).__name__}")
        backoff = checks.positive("backoff", backoff, strict=False)  # numpy's numbers pass too
        cold_starts = checks.integer("cold_starts", cold_starts, minimum=1)
        jit_opt = checks.integer("jit_opt", jit_opt, minimum=0)
        seed = None if seed is None else checks.integer("seed", seed, minimum=0)
        cap = RT_SHARE * scenario.dt if max_solve_time is None else max_solve_time
        cap = checks.real("max_solve_time", cap)
        if not cap > 0:
            raise ValueError(f"max_solve_time must be a time > 0 [s] (or None), got {max_solve_time!r}")
        self.max_solve_time = float(cap)
        """The wall-time cap of one step [s]."""
        self.scenario = scenario
        self.slots = check_slots(object_slots, scenario)
        """K, the object slots (fixed at construction)."""
        chosen = None if predictor in (None, "constant") else make_predictor(predictor, scenario)
        self._slots = Slots(scenario, self.slots, chosen, modes)
        self.mode_threshold = check_threshold(mode_threshold)
        """$w_{min}$: the RMPC plans against every mode of at least this weight (the SMPC: all)."""
        self._numbers = self._slots.numbers
        scenarios = [self._slots.scenario_of(row) for row in range(self._slots.rows)]
        self.estimators: tuple[RiskEstimator, ...] = tuple(with_bodies(self._estimator(s)) for s in scenarios)
        """Each planning row's risk estimator (object k's radius, mass and uncertainty; row k M + m)."""
        self.estimator = self.estimators[0]
        self._worsts = tuple(with_bodies(WorstCaseRisk(s)) for s in scenarios)
        self.risk_tolerance = scenario.risk_tolerance if risk_tolerance is None else risk_tolerance
        self._speed_limit = math.inf
        self.settings = SolverSettings(
            solver=solver,
            stage_cost=stage_cost,
            jit=bool(jit),
            jit_opt=jit_opt,
            jit_cache=jit_cache,
            tol=tol,
            max_iter=max_iter,
            warm_start=bool(warm_start),
            restart_standing=bool(restart_standing),
            solver_options=dict(solver_options or {}),
            time_limit=self.max_solve_time if math.isfinite(self.max_solve_time) else None,
            rungs=RUNGS if math.isfinite(self.max_solve_time) else 1,
            soft_penalty=soft_penalty,
        )
        """How the NLP is solved (:class:`agents.mpc.nlp.settings.SolverSettings`)."""
        self.backoff = float(backoff)
        self.cold_starts = cold_starts
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.failures = 0
        self.last_solve: SolveReport | None = None
        self.last_solves: list[SolveReport] = []
        self._memory: dict[int, dict[str, Any]] = {}
        self._problems: dict[tuple[str, int], Problem] = {}
        self._maps: dict[tuple[str, str, str], np.ndarray] = {}
        self._manoeuvre_time = MANOEUVRE_TIME
        variant = self._risk_variant()
        variants = ("free", variant, soft_variant(variant))
        # given beliefs: the NLPs of as many rows as a step needs are built when it first does, but
        # a capped step must never build (the cap would cut it): a capped agent builds all now
        built = [self._problem(v, 1 if self._slots.given else None) for v in variants]
        prepared = self.prepare() if math.isfinite(self.max_solve_time) else 0.0
        self.build_time = sum(p.build_time for p in built) + prepared
        """Seconds spent building the solvers at construction (capped: all, :meth:`prepare`)."""

    # ------------------------------------------------------------------ public API
    @property
    def risk_tolerance(self) -> float:
        r"""$\epsilon$ [units of the severity]; a solver parameter, so it may change between steps."""
        return self._epsilon

    @risk_tolerance.setter
    def risk_tolerance(self, value: float) -> None:
        value = checks.real("risk_tolerance", value)
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"risk_tolerance must be a finite number >= 0, got {value!r}")
        s = self.estimator.severity
        self._epsilon = checks.within_severity("risk_tolerance", value, s.name, s.upper_bound, s.unit)

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

    def prepare(self) -> float:
        """Build every NLP a step can run (a capped agent did at construction): the free problem and
        each form of :meth:`_step_forms`, hard and soft, at every row count of
        :meth:`agents.mpc.objects.Slots.capacities`. Returns the seconds spent building."""
        rows, known = self._slots.capacities(self._risk_parameter_shape()[0] > 0), set(self._problems)
        forms = [v for f in sorted(self._step_forms()) for v in (f, soft_variant(f))]
        _ = [self._problem(v, r) for v in ("free", *forms) for r in rows]
        return sum(p.build_time for key, p in self._problems.items() if key not in known)

    def reset(self, seed: int | None = None) -> None:
        """Forget warm starts and plans, zero :attr:`failures`, re-seed the generator (``seed``)."""
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
        r"""SB3's predictor protocol: float32 action(s) ($v$ [m/s], $\omega$ [rad/s]) and no state.

        ``observation``: one ``(10 + 6 K,)`` (K: :attr:`slots`) or a batch ``(B, 10 + 6 K)``, each solved in
        turn with its own warm start (by batch index); the plan respects every present object's risk bound
        (another slot count: ``ValueError``). ``episode_start`` (bool or ``(B,)``) drops the warm start; so
        does a new episode detected from the observation (its last applied input is not the action
        returned, or the ego is over 1 m from where the plan put it)."""
        size = ob.size(self.slots)
        forget = lambda i: self._memory.pop(i, None)  # noqa: E731  (a new episode of batch entry i)
        actions, reports = predict_each(observation, size, episode_start, forget, self._step)
        self.last_solves = reports
        self.last_solve = reports[-1]
        return actions, None

    def _risk_numpy(
        self, ego: np.ndarray, futures: list[Belief | None], data: np.ndarray, weights: Any = None
    ) -> np.ndarray:
        r"""Risk ``(N,)`` of ego states ``(N, 4)``: the sum over the present rows (``futures[k]``
        not None) of their risks at $n = 1, \dots, N$, each times its mode's weight where the risk is an
        expectation (:attr:`WEIGHTED`); zeros when no object is present."""
        rows = data.shape[1] // len(futures) if data.size else 0
        terms = [
            self._slot_risk(k, ego, f, data[:, k * rows : (k + 1) * rows])
            * (weights[k] if self.WEIGHTED and weights is not None and self._slots.given else 1.0)
            for k, f in enumerate(futures)
            if f is not None
        ]
        return combine(terms) if terms else np.zeros(np.shape(ego)[:-1])

    def _risk_variant(self, epsilon: float | None = None) -> str:
        """The risk rows' form at ``epsilon`` (default: the agent's)."""
        epsilon = self._epsilon if epsilon is None else epsilon
        return "zero" if self.ZERO_TOLERANCE_VARIANT and epsilon <= 0.0 else "general"

    def _problem(self, variant: str, rows: int | None = None) -> Problem:
        """The built NLP of ``variant`` with ``rows`` rows of beliefs (default: every row). Packed
        rows: the free problem runs only when no row is active, so at one row (else: its rollout)."""
        packed = self._slots.capacities(self._risk_parameter_shape()[0] > 0)[0] is not None
        rows = 1 if variant == "free" and packed else self._slots.rows if rows is None else rows
        if (variant, rows) not in self._problems:
            key = (
                type(self).__name__,
                variant,
                problem_key(self.scenario),  # not epsilon, v_ref, the uncertainty, objects: parameters
                rows,
                self._slots.given,
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
                rows,
                self._slots.given,
            )
            self._problems[variant, rows] = cached_problem(key, build)
        return self._problems[variant, rows]

    def _risk_possible(self, x0: np.ndarray, future: Belief, slot: int = 0) -> bool:  # slot's object
        return measure.risk_possible(self.scenario, x0, future, float(self._numbers[slot, 0]))

    def _call(
        self, pr: Problem, args: dict[str, Any], rung: int = 0
    ) -> tuple[dict[str, np.ndarray], str, bool, int, dict]:
        """One solver call (:func:`agents.mpc.nlp.calls.call_solver`); a method so tests can watch it."""
        return call_solver(pr, args, self.settings.solver, rung)

    def _step(self, index: int, obs_vec: np.ndarray) -> SolveReport:
        """One step for the observation ``obs_vec`` (10 + 6 K,) of batch entry ``index``: measure
        (:meth:`_measure`), run the step pipeline (:class:`agents.mpc.step.Step`) within the
        wall-time cap, keep what it says to keep."""
        collecting = gc.isenabled()
        gc.disable()  # no garbage-collection pause inside the step: it runs between steps
        try:
            with Budget.open(self.max_solve_time) as budget:
                data = self._measure(index, obs_vec)
                result = Step(self._context(data), data, budget).run()
        finally:
            if collecting:
                gc.enable()
        self._memory[index] = result.memory
        self._manoeuvre_time = result.manoeuvre_time
        self.failures += int(result.failed)
        return result.report

    def _context(self, data: StepInput | None = None) -> StepContext:
        r"""What a step uses that the controller has (risk with the rows' weights, $\epsilon$: ``data``'s)."""
        weights = None if data is None else data.weights
        epsilon = self._epsilon if data is None else data.epsilon
        rows = self._slots.rows if data is None or data.rows is None else data.rows
        return StepContext(
            scenario=self.scenario,
            settings=self.settings,
            problem=functools.partial(self._problem, rows=rows),
            built={v: pr for (v, r), pr in self._problems.items() if r == rows},
            call=self._call,
            risk=functools.partial(self._risk_numpy, weights=weights),
            worsts=self._worsts,
            pilot=functools.partial(self._pilot_plan, epsilon=epsilon),
            maps=self._maps,
            epsilon=epsilon,
            backoff=self.backoff,
            cold_starts=self.cold_starts,
            max_solve_time=self.max_solve_time,
            manoeuvre_time=self._manoeuvre_time,
        )

    @property
    def speed_limit(self) -> float:
        """A cap [m/s] on $v_{ref}$ from the next step (a stop ahead: the junction gate's); inf: none."""
        return self._speed_limit

    @speed_limit.setter
    def speed_limit(self, value: float) -> None:
        inf = not isinstance(value, bool) and value == math.inf
        self._speed_limit = math.inf if inf else checks.positive("speed_limit", value, strict=False)

    def _measure(self, index: int, obs_vec: np.ndarray) -> StepInput:
        r"""The step's data from the observation: the memory (None: a new episode), $x_0$, each present
        slot's beliefs at $n = 1, \dots, N$, the active slots, the variant, the risk data, the parameters."""
        o = ob.split(obs_vec, slots=self.slots)
        memory = self._memory.get(index)
        memory = None if memory is None or measure.new_episode(memory, o) else memory
        x0 = measure.measured_state(self.scenario, o)
        futures, weights, hypotheses = self._slots.beliefs(self._problem("free"), o)
        # active: present, counted (the RMPC: hypothesis weight >= w_min), may reach the ego in time
        floor = self.mode_threshold if not self.WEIGHTED else 0.0
        counts = [f is not None and weights[k] > 0 and hypotheses[k] >= floor for k, f in enumerate(futures)]
        active = np.array([c and self._risk_possible(x0, futures[k], k) for k, c in enumerate(counts)])
        epsilon = self._step_epsilon(index, memory is None)
        variant = self._risk_variant(epsilon) if active.any() else "free"
        data = self._risk_data(futures)
        terms = self._terms_parameters(index, memory is None)
        objects = np.repeat(o.objects, self._slots.modes, axis=0)
        rows, keep = self._slots.packing(active, data.size > 0)
        v_ref = min(self.scenario.ego.v_ref, self._speed_limit)
        p = parameter_vector(epsilon, v_ref, objects[keep], active[keep], self._numbers[keep], data, terms)
        packed = [futures[j] if active[j] else None for j in keep]
        p = np.concatenate([p, self._slots.given_block(packed, weights[keep])])
        return StepInput(
            index, obs_vec, memory, x0, futures, active, variant, data, p, weights, epsilon, rows
        )
