"""The path-following MPC controller: one step = measure, choose the NLP variant, warm-start,
solve, fall back; SB3's ``predict`` on top.

The optimal control problem is in :mod:`agents.ocp`, its solver (options, compilation, caches) in
:mod:`agents.solver`, the cold-start initial guesses in :mod:`agents.guesses`. The controller adds:

- **Variant choice**: ``"free"`` (no risk rows) when no step's risk can be nonzero anywhere the ego
  can reach within the horizon (distance to the truncation box minus the distance reachable under
  the bounds and rate limits exceeds r_e + r_o + :data:`FREE_MARGIN`), else the agent's risk form.
- **Initial guess**: the previous solution shifted by one stage (inputs shifted, the last repeated,
  states re-simulated from the measurement) with its shifted multipliers. The first solve of an
  episode solves from each of a few rollouts (brake, track the path, reverse) and keeps the plan of
  least cost; a subclass may instead hand it the plan of a cheaper pilot problem
  (:meth:`PathFollowingMPC._pilot_plan`, the Monte Carlo SMPC's 100-draw pilot), which did that.
- **Fallback** when every attempt fails (see :class:`PathFollowingMPC`).
"""

from __future__ import annotations

import functools
import math
import os
import time
import warnings
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from agents import guesses
from agents.base import SolveReport, as_batch
from agents.fallback import fallback_plan, feasible_action
from agents.ocp import STAGE_COSTS, problem_key, uncertainty_vector, variable_bounds
from agents.solver import (
    DEFAULT_JIT_CACHE,
    SOLVERS,
    Problem,
    SolverSettings,
    build_problem,
    cached_problem,
    call_solver,
)
from risk_env import observation as ob
from risk_env.ops import NUMPY
from risk_env.path import point
from risk_env.prediction import Belief
from risk_env.risk import signed_box_distance
from risk_env.scenario import Scenario

__all__ = ["FREE_MARGIN", "SOLVERS", "STAGE_COSTS", "PathFollowingMPC"]

FREE_MARGIN = 0.5
"""Extra distance [m] the reachable set must keep from every box for the ``"free"`` variant."""
PLANS_AGAINST_ONE = (
    "this MPC plans against the first present object of its observation only; the scenario's other"
    " objects carry no risk constraint (issue 10, items 4-5)"
)


class PathFollowingMPC:
    """Path-following MPC with a risk constraint; the subclasses say which (:class:`agents.RMPC`,
    :class:`agents.SMPC`). The problem is in :mod:`agents.ocp`, its solver in :mod:`agents.solver`.

    Fallback when a solve fails (infeasible, iteration limit, NaN, an exception): a warm-started
    call is retried cold from the best initial-guess rollouts (up to ``cold_starts``); if those fail
    too, the agent applies the next input of the last successful plan while one is left
    (``"shifted_plan"``), and after that brakes, v and omega toward 0 as fast as the rate limits
    allow (``"brake"``; :mod:`agents.fallback`). It never raises inside an episode and never
    returns NaN; each failure is marked in :attr:`last_solve`
    (``fallback``) and counted in :attr:`failures` (reset by :meth:`reset`). A success is IPOPT's
    "Solve_Succeeded" or "Solved_To_Acceptable_Level", fatrop's success flag, with finite numbers.

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
        cold_starts: how many initial-guess rollouts (best first) a step may try from cold, after
            a failed warm start; the first step of an episode solves from each of them and keeps
            the plan of least cost (the problem is not convex: going round the object on either
            side, waiting or reversing are separate local optima).
        solver_options: extra nlpsol options; ``{"ipopt": {...}}`` / ``{"fatrop": {...}}`` update
            the plugin's own options.
        seed: seed of the agent's generator (Monte Carlo draws).
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
    ) -> None:
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a risk_env Scenario, got {type(scenario).__name__}")
        if not (isinstance(backoff, (int, float)) and backoff >= 0):
            raise ValueError(f"backoff must be >= 0, got {backoff!r}")
        if isinstance(cold_starts, bool) or not isinstance(cold_starts, int) or cold_starts < 1:
            raise ValueError(f"cold_starts must be an integer >= 1, got {cold_starts!r}")
        self.scenario = scenario
        if len(scenario.objects) > 1:
            warnings.warn(PLANS_AGAINST_ONE, stacklevel=2)
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
        self._g_maps: dict[tuple[str, str], np.ndarray] = {}
        ego, dt = scenario.ego, scenario.dt
        self._speed_cap = max(abs(ego.v_min), abs(ego.v_max))
        self._dv = ego.accel_max * dt
        built = [self._problem(v) for v in ("free", self._risk_variant())]
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

        ``observation``: one ``(10 + 6 K,)`` (K slots: the scenario's objects) or a batch ``(B, 10 + 6 K)``,
        each solved in turn with its own warm start (by batch index); the plan respects the first
        present object's risk bound. ``episode_start`` (bool or ``(B,)``) drops the warm start;
        so does a new episode detected from the observation (its last applied input is not the
        action returned, or the ego is over 1 m from where the plan put it).
        """
        obs, single = as_batch(observation, ob.size(len(self.scenario.objects)))
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

    def _risk_parameter_shape(self) -> tuple[int, int]:
        """Shape of the per-step risk data parameter ((0, 0): none)."""
        return (0, 0)

    def _margin(self, ego: ca.SX, belief: Belief, epsilon: ca.SX, data: ca.SX, zero: bool) -> ca.SX:
        """Symbolic constraint, >= 0 iff the risk bound holds at this step; ``zero``: the form for
        epsilon = 0 (only with :attr:`ZERO_TOLERANCE_VARIANT`)."""
        raise NotImplementedError

    def _pilot_plan(self, index: int, obs_vec: np.ndarray, variant: str) -> tuple[np.ndarray, int] | None:
        """A cold start's first initial guess: inputs ``(N, NU)`` planned on a cheaper problem, and
        the solver iterations that took; None: start from the rollouts."""
        return None

    def _risk_data(self, beliefs: Belief) -> np.ndarray:
        """Per-step risk data ``(N, *shape)`` for one solve (Monte Carlo: fresh draws)."""
        return np.zeros((self.horizon, 0, 0))

    def _risk_numpy(self, ego: np.ndarray, beliefs: Belief, data: np.ndarray) -> np.ndarray:
        """Risk ``(N,)`` of ego states ``(N, 4)`` against the beliefs at n = 1..N."""
        raise NotImplementedError

    # ------------------------------------------------------------------ building
    def _risk_variant(self) -> str:
        return "zero" if self.ZERO_TOLERANCE_VARIANT and self._epsilon <= 0.0 else "general"

    def _problem(self, variant: str) -> Problem:
        if variant not in self._problems:
            key = (
                type(self).__name__,
                variant,
                problem_key(self.scenario),  # neither epsilon nor the uncertainty: parameters
                self._estimator_key(),  # also for "free": the parameter layout (e.g. draws) differs
                self.settings.key(),
            )
            build = functools.partial(
                build_problem,
                self.scenario,
                variant,
                self.settings,
                self._margin,
                self._risk_parameter_shape(),
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

    def _risk_possible(self, x0: np.ndarray, future: Belief) -> bool:
        """Whether some step's risk could be nonzero where the ego can reach (else: ``"free"``)."""
        distance = signed_box_distance(x0[0] - future.x, x0[1] - future.y, future.half_x, future.half_y)
        spare = distance - self._reach(x0[4]) - self.scenario.collision_distance
        return bool(np.any(spare <= FREE_MARGIN))

    def _g_map(self, old: Problem, new: Problem) -> np.ndarray:
        """For each row of ``new``, the row of ``old`` one stage later (-1: none)."""
        key = (old.variant, new.variant)
        if key not in self._g_maps:
            where = {tag: i for i, tag in enumerate(old.g_tags)}
            self._g_maps[key] = np.array(
                [where.get((s + 1, k, c), where.get((s, k, c), -1)) for s, k, c in new.g_tags], dtype=int
            )
        return self._g_maps[key]

    def _warm_guess(
        self, pr: Problem, mem: dict[str, Any], x0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The previous solution shifted by one stage, states re-simulated from ``x0``."""
        prev_inputs = mem["w"][pr.u_index]
        shifted = np.vstack([prev_inputs[1:], prev_inputs[-1:]])
        w0 = guesses.pack(pr, guesses.rollout(pr, x0, shifted), shifted)
        if not self.settings.warm_start or self.settings.solver != "ipopt":
            return w0, None, None
        old = self._problems[mem["variant"]]
        g_map = self._g_map(old, pr)
        lam_g = np.where(g_map >= 0, mem["lam_g"][np.maximum(g_map, 0)], 0.0)
        return w0, mem["lam_x"][pr.shift_w], lam_g

    def _call(self, pr: Problem, args: dict[str, Any]) -> tuple[dict[str, np.ndarray], str, bool, int, dict]:
        """One solver call (:func:`agents.solver.call_solver`); a method so tests can watch it."""
        return call_solver(pr, args, self.settings.solver)

    def _step(self, index: int, obs_vec: np.ndarray) -> SolveReport:
        t_start = time.perf_counter()
        o = ob.split(obs_vec)
        sc = self.scenario
        mem = self._memory.get(index)
        if mem is not None and self._new_episode(mem, o):
            mem = None
        x0 = self._measured_state(o)
        base = self._problem("free")
        uncertainty = uncertainty_vector(sc)
        future = Belief.from_array(np.asarray(base.beliefs(o.object_measurement, uncertainty))[1:])
        variant = self._risk_variant() if self._risk_possible(x0, future) else "free"
        pr = self._problem(variant)
        data = self._risk_data(future)
        p = np.concatenate(
            [o.object_measurement, [self._epsilon], uncertainty, *(d.ravel(order="F") for d in data)]
        )
        lbx, ubx = variable_bounds(sc, pr.x_index, pr.u_index, pr.n_w, x0)
        lbg = pr.lbg.copy()
        lbg[pr.risk_rows] = self.backoff

        # --- solve: warm start from the shifted plan; else, or on failure, cold from the rollouts.
        # An episode's first step solves from every rollout (up to cold_starts) and keeps the best.
        warm = mem is not None and mem.get("w") is not None
        first = mem is None
        iterations, status, ok, out, timings, t_solver = 0, "not solved", False, {}, {}, 0.0
        best: tuple[dict[str, np.ndarray], str, dict[str, float]] | None = None
        cold: list[np.ndarray] | None = None
        planned = None if warm else self._pilot_plan(index, obs_vec, variant)
        pilot = None
        if planned is not None:  # the pilot's plan first; its own cold start chose among the rollouts
            inputs, iterations = planned
            pilot = guesses.pack(pr, guesses.rollout(pr, x0, inputs), inputs)
        for attempt in range(int(warm or pilot is not None) + self.cold_starts):
            if warm and attempt == 0:
                w0, lam_x, lam_g = self._warm_guess(pr, mem, x0)
            elif pilot is not None and attempt == 0:
                w0, lam_x, lam_g = pilot, None, None
            else:
                cold = guesses.cold_guesses(pr, sc, x0, p, lbg) if cold is None else cold
                skip = int(warm or pilot is not None)
                if attempt - skip >= len(cold):
                    break
                w0, lam_x, lam_g = cold[attempt - skip], None, None
            args = {"x0": w0, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": pr.ubg, "p": p}
            if lam_x is not None:
                args.update(lam_x0=lam_x, lam_g0=lam_g)
            t0 = time.perf_counter()
            out, status, ok, iters, timings = self._call(pr, args)
            t_solver += time.perf_counter() - t0
            iterations += iters
            if ok and (best is None or out["f"][0] < best[0]["f"][0]):
                best = (out, status, timings)
            if ok and (not first or (pilot is not None and attempt == 0)):
                break
        retried = best is not None and attempt > 0 and not first
        ok = best is not None
        if ok:
            out, status, timings = best

        # --- the plan, or the fallback
        if ok:
            w = np.clip(out["x"], lbx, ubx)
            states, inputs = w[pr.x_index], w[pr.u_index]
            action = feasible_action(sc, inputs[0, :2], x0[4:6])
            fallback, cost = None, float(out["f"][0])
            mem = {
                "w": w,
                "lam_x": out["lam_x"],
                "lam_g": out["lam_g"],
                "variant": variant,
                "plan": inputs,
                "used": 0,
            }
        else:
            self.failures += 1
            fallback, inputs, mem = fallback_plan(sc, x0, mem)
            action = feasible_action(sc, inputs[0, :2], x0[4:6])
            inputs = inputs.copy()
            inputs[0, :2] = action
            states = guesses.rollout(pr, x0, inputs)
            cost = float("nan")
        action = action.astype(np.float32)
        mem["action"] = action
        mem["predicted"] = states[1, :2].copy()
        self._memory[index] = mem

        ego_states = states[1:, [0, 1, 2, 4]]  # pose of state n with the speed v_{n-1} that led there
        return SolveReport(
            solve_time=time.perf_counter() - t_start,
            success=ok,
            status=status,
            iterations=iterations,
            fallback=fallback,
            action=action,
            ego_trajectory=states[:, :3].copy(),
            inputs=inputs[:, :2].copy(),
            path_speed=inputs[:, 2].copy(),
            lambdas=states[:, 3].copy(),
            risk_fn=functools.partial(self._risk_numpy, ego_states, future, data),
            risk_tolerance=self._epsilon,
            cost=cost,
            retried=retried,
            solver_time=t_solver,
            variant=variant,
            timings=timings,
        )

    def _new_episode(self, mem: dict[str, Any], o: ob.Observation) -> bool:
        """The observation does not continue the episode this memory belongs to."""
        if "action" not in mem or np.max(np.abs(o.ego_input - mem["action"])) > 1e-3:
            return True
        return bool(np.hypot(*(o.ego_pose[:2] - mem["predicted"])) > 1.0)
