"""The path-following MPC core (paper Secs. III-VI), built once, called with parameters, warm-started.

The optimal control problem, in the order of the sections of :meth:`PathFollowingMPC._build`:

- **Variables** (multiple shooting, stage-wise as fatrop expects): per stage n = 0..N the state
  ``x_n = (c1, c2, theta, lambda, v_{n-1}, omega_{n-1})`` and per n = 0..N-1 the input
  ``u_n = (v, omega, u2)``. The state carries the previous input so that the rate limits and the
  risk's ego speed are stage-local. ``x_0`` is fixed by its bounds (lbx = ubx) to the measurement:
  the ego pose (heading unwrapped near theta_P(lambda_k)), the last applied input and lambda_k, the
  observation's closest-point progress.
- **Dynamics**: the ego unicycle (:func:`risk_env.dynamics.casadi_step`) and the timing law
  ``lambda_{n+1} = lambda_n + u2 cos(theta_n - theta_P(lambda_n)) T`` (:func:`risk_env.path.timing_law`).
- **Objective**: ``sum e' W e``, ``e = (c1 - c1_P(lambda), c2 - c2_P(lambda), theta - theta_P(lambda),
  u2 - v_ref)`` (:func:`risk_env.path.path_error` with the unwrapped heading), no terminal cost.
  ``stage_cost="reached"`` (default) sums the pose part over the states n = 1..N that the inputs
  reach and the speed part over u2_0..u2_{N-1}. The paper's sum over n = 0..N-1
  (``stage_cost="paper"``) holds a constant pose term at n = 0 and leaves the last input
  (v, omega)_{N-1} without any cost (it only moves x_N, which nothing weighs), so its optimum is not
  unique there.
- **Constraints**: ``v in [v_min, v_max]``, ``|omega| <= omega_max``; rate limits
  ``|v_n - v_{n-1}| <= accel_max T``, ``|omega_n - omega_{n-1}| <= omega_rate_max T`` with
  (v, omega)_{-1} the last applied input; ``u2 in [v_min, v_max]`` (the paper's u2 in V_e, the
  ego's own speed set, so the reference point may wait or step back with a reversing ego);
  ``lambda_n >= lambda_0`` (the path's start) and no upper cap (the path continues beyond the goal);
  the subclass's risk constraint ``margin_n >= backoff`` for n = 1..N at the ego's predicted state n
  with speed v_{n-1} (the input that led there: the env's R_{k+1|k}), against the object's belief at
  step n, :func:`risk_env.predict` built symbolically on the object-measurement parameter.
- **Parameters** (nlpsol ``p``): the object measurement (c1, c2, theta, v, omega), epsilon, the
  numbers of the scenario's :class:`~risk_env.scenario.Uncertainty` (sigma0, growths, box, speed
  bounds) and the subclass's risk data (Monte Carlo draws). Agents that differ only in their
  tolerance or uncertainty level share one built (or compiled) solver (cached per process, and on
  disk when compiled).
- **Variants** of the same NLP, each built once: ``"general"``; ``"zero"`` (the subclass's exact
  form at epsilon = 0); ``"free"``, without risk rows, used when no step's risk can be nonzero
  anywhere the ego can reach within the horizon (distance to the truncation box minus the distance
  reachable under the bounds and rate limits exceeds r_e + r_o): then the constraints cannot bind
  and the free problem has the same solution, at a fraction of the cost.
- **Initial guess**: the previous solution shifted by one stage (inputs shifted, the last repeated,
  states re-simulated from the measurement) with its shifted multipliers. The first solve of an
  episode solves from each of a few rollouts (brake, track the path, reverse) and keeps the plan of
  least cost; a subclass may instead hand it the plan of a cheaper pilot problem
  (:meth:`PathFollowingMPC._pilot_plan`, the Monte Carlo SMPC's 100-draw pilot), which did that.
- **Compiled solvers** (``jit=True``): the same NLP is assembled once more in MX with the stage
  functions (dynamics, pose cost, risk row) called rather than inlined, its functions (the NLP and
  the derivatives the solver evaluates) generated as C by :class:`casadi.CodeGenerator`, compiled
  by ``$CC`` (gcc) at ``-O{jit_opt}`` into a shared library in a private temporary directory and
  kept in ``jit_cache`` under a hash of the NLP, so later processes load it; nlpsol then runs from
  the library. Nothing is written to the working directory and the process never changes
  directory. Timings: ``python -m benchmarks.timing --jit`` and the README.

Solvers (:data:`SOLVERS`): ``"fatrop"`` (default; stage-wise structure detected by CasADi, a
Riccati-based interior point method; primal warm start) and ``"ipopt"`` (exact Hessian, MUMPS,
adaptive barrier, primal-dual warm start; IPOPT's "Solved To Acceptable Level" counts as a
success). On the paper's 36 closed loops (``python -m benchmarks.timing``, 2 cores) fatrop took a
median / p95 of 2.1 / 4.6 ms per RMPC step against IPOPT's 6.6 / 20 ms (IPOPT spends ~2.5 ms per
call in MUMPS and its own set-up however small the problem), and 6.3 / 23 ms per exact-SMPC step
against 7.2 / 41 ms, neither with a failed solve. The two may settle in different local optima.
"""

from __future__ import annotations

import atexit
import dataclasses
import functools
import hashlib
import math
import os
import shlex
import shutil
import subprocess
import tempfile
import time
import warnings
from collections import OrderedDict
from dataclasses import dataclass, replace
from types import SimpleNamespace
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from agents.base import SolveReport, as_batch
from risk_env import observation as ob
from risk_env.dynamics import casadi_step
from risk_env.ops import CASADI, NUMPY
from risk_env.path import path_error, point, timing_law
from risk_env.prediction import Belief, predict
from risk_env.risk import signed_box_distance
from risk_env.scenario import Scenario

SOLVERS: tuple[str, ...] = ("fatrop", "ipopt")
STAGE_COSTS: tuple[str, ...] = ("reached", "paper")
VARIANTS: tuple[str, ...] = ("general", "zero", "free")
NX = 6
"""Stage state: c1 [m], c2 [m], theta [rad], lambda [m], previous v [m/s], previous omega [rad/s]."""
NU = 3
"""Stage input: v [m/s], omega [rad/s], u2 [m/s]."""
IPOPT_SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
FREE_MARGIN = 0.5
"""Extra distance [m] the reachable set must keep from every box for the ``"free"`` variant."""
DEFAULT_JIT_CACHE = os.environ.get(
    "RISKMPC_JIT_CACHE", os.path.join(os.path.expanduser("~"), ".cache", "riskcrossing", "jit")
)
"""Where compiled solvers (shared libraries) are kept between processes."""
_COMPILED_FUNCTIONS = ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l", "nlp_grad")
"""The nlpsol functions a compiled solver takes from its shared library (the rest are derived)."""
_CACHE_SIZE = 48
_SOLVER_CACHE: OrderedDict[Any, _Problem] = OrderedDict()


def have_c_compiler() -> bool:
    """Whether the C compiler for compiled solvers (``$CC``, e.g. ``"ccache gcc"``, or ``gcc``) can
    be found."""
    command = shlex.split(os.environ.get("CC", "gcc"))
    return bool(command) and shutil.which(command[0]) is not None


@dataclass(frozen=True)
class _Problem:
    """One built NLP variant: the solver, an evaluator and the index maps of its layout."""

    variant: str
    solver: ca.Function
    evaluate: ca.Function
    """(w, p) -> (objective, g): scores initial-guess candidates."""
    rollout: ca.Function
    """(x_0 (NX,), inputs (NU, N)) -> states (NX, N): the model f, accumulated."""
    beliefs: ca.Function
    """object measurement (5,) -> (N+1, 11) belief fields at n = 0..N (``Belief.as_array`` order)."""
    lbg: np.ndarray
    ubg: np.ndarray
    x_index: np.ndarray
    """(N+1, NX) positions of the states in w."""
    u_index: np.ndarray
    """(N, NU) positions of the inputs in w."""
    risk_rows: np.ndarray
    """Rows of g holding margin_n, n = 1..N (empty for ``"free"``)."""
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

    @property
    def n_w(self) -> int:
        return len(self.w_tags)


class PathFollowingMPC:
    """Path-following MPC with a risk constraint; the subclasses say which (:class:`agents.RMPC`,
    :class:`agents.SMPC`). The problem is described in :mod:`agents.mpc`.

    Fallback when a solve fails (infeasible, iteration limit, NaN, an exception): a warm-started
    call is retried cold from the best initial-guess rollouts (up to ``cold_starts``); if those fail
    too, the agent
    applies the next input of the last successful plan while one is left (``"shifted_plan"``), and
    after that brakes, v and omega toward 0 as fast as the rate limits allow (``"brake"``). It never
    raises inside an episode and never returns NaN; each failure is marked in :attr:`last_solve`
    (``fallback``) and counted in :attr:`failures` (reset by :meth:`reset`). A success is IPOPT's
    "Solve_Succeeded" or "Solved_To_Acceptable_Level", fatrop's success flag, with finite numbers.

    Args:
        scenario: the case study; its ``risk_tolerance`` is epsilon unless overridden.
        risk_tolerance: epsilon [units of the severity], >= 0; overrides the scenario's.
        solver: one of :data:`SOLVERS`.
        stage_cost: one of :data:`STAGE_COSTS` (see :mod:`agents.mpc`).
        jit: run the solver on compiled code (see "Compiled solvers" in :mod:`agents.mpc`); falls
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
        if solver not in SOLVERS:
            raise ValueError(f"unknown solver {solver!r}; expected one of {SOLVERS}")
        if stage_cost not in STAGE_COSTS:
            raise ValueError(f"unknown stage_cost {stage_cost!r}; expected one of {STAGE_COSTS}")
        if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1:
            raise ValueError(f"max_iter must be an integer >= 1, got {max_iter!r}")
        if not (isinstance(tol, (int, float)) and tol > 0):
            raise ValueError(f"tol must be > 0, got {tol!r}")
        if not (isinstance(backoff, (int, float)) and backoff >= 0):
            raise ValueError(f"backoff must be >= 0, got {backoff!r}")
        if isinstance(cold_starts, bool) or not isinstance(cold_starts, int) or cold_starts < 1:
            raise ValueError(f"cold_starts must be an integer >= 1, got {cold_starts!r}")
        self.scenario = scenario
        self.risk_tolerance = scenario.risk_tolerance if risk_tolerance is None else risk_tolerance
        self.solver_name = solver
        self.stage_cost = stage_cost
        self.jit = bool(jit)
        self.jit_opt = int(jit_opt)
        self.jit_cache = jit_cache
        self.tol = float(tol)
        self.max_iter = max_iter
        self.warm_start = bool(warm_start)
        self.backoff = float(backoff)
        self.cold_starts = cold_starts
        self.solver_options = dict(solver_options or {})
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.failures = 0
        self.last_solve: SolveReport | None = None
        self.last_solves: list[SolveReport] = []
        self._memory: dict[int, dict[str, Any]] = {}
        self._problems: dict[str, _Problem] = {}
        self._g_maps: dict[tuple[str, str], np.ndarray] = {}
        ego, dt = scenario.ego, scenario.dt
        self._speed_cap = max(abs(ego.v_min), abs(ego.v_max))
        self._dv, self._dw = ego.accel_max * dt, ego.omega_rate_max * dt
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

        ``observation``: one ``(15,)`` or a batch ``(B, 15)``, each solved in turn with its own
        warm start (by batch index). ``episode_start`` (bool or ``(B,)``) drops the warm start;
        so does a new episode detected from the observation (its last applied input is not the
        action returned, or the ego is over 1 m from where the plan put it).
        """
        obs, single = as_batch(observation, ob.SIZE)
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

    def _problem(self, variant: str) -> _Problem:
        if variant not in self._problems:
            key = (
                type(self).__name__,
                variant,
                _problem_key(self.scenario),  # neither epsilon nor the uncertainty: parameters
                self._estimator_key(),  # also for "free": the parameter layout (e.g. draws) differs
                self.solver_name,
                self.stage_cost,
                self.jit,
                self.jit_opt,
                self.tol,
                self.max_iter,
                self.warm_start,
                repr(sorted(self.solver_options.items())),
            )
            if key in _SOLVER_CACHE:
                _SOLVER_CACHE.move_to_end(key)
                self._problems[variant] = replace(_SOLVER_CACHE[key], build_time=0.0)
            else:
                problem = self._build(variant)
                _SOLVER_CACHE[key] = problem
                while len(_SOLVER_CACHE) > _CACHE_SIZE:
                    _SOLVER_CACHE.popitem(last=False)
                self._problems[variant] = problem
        return self._problems[variant]

    def _plugin_options(self) -> dict[str, Any]:
        extra = {k: v for k, v in self.solver_options.items() if k not in SOLVERS}
        if self.solver_name == "ipopt":
            ipopt = {
                "print_level": 0,
                "sb": "yes",
                "tol": self.tol,
                "constr_viol_tol": 1e-6,
                "acceptable_tol": max(1e-3, 10 * self.tol),
                "acceptable_constr_viol_tol": 1e-5,
                "acceptable_iter": 5,
                "max_iter": self.max_iter,
                "mu_strategy": "adaptive",
                "hessian_approximation": "exact",
            }
            if self.warm_start:
                ipopt.update(
                    warm_start_init_point="yes",
                    warm_start_bound_push=1e-6,
                    warm_start_mult_bound_push=1e-6,
                    mu_init=1e-3,
                )
            ipopt.update(self.solver_options.get("ipopt", {}))
            return {"ipopt": ipopt, **extra}
        # CasADi 3.8's fatrop takes a primal initial guess only (no warm_start_* options); a small
        # initial barrier and bound push suit that guess, the shifted previous solution
        fatrop = {
            "print_level": 0,
            "tol": self.tol,
            "constr_viol_tol": 1e-6,
            "max_iter": self.max_iter,
            "mu_init": 1e-3 if self.warm_start else 1e-1,
            "bound_push": 1e-6 if self.warm_start else 1e-2,
            "bound_frac": 1e-6 if self.warm_start else 1e-2,
        }
        fatrop.update(self.solver_options.get("fatrop", {}))
        return {"structure_detection": "auto", "fatrop": fatrop, **extra}

    def _build(self, variant: str) -> _Problem:
        t0 = time.perf_counter()
        sc = self.scenario
        N, dt, path, ego = sc.horizon, sc.dt, sc.path, sc.ego
        w_c1, w_c2, w_th, w_v = sc.cost_weights

        # --- stage functions: ego model with the timing law, pose error, the risk row
        x, u = ca.SX.sym("x", NX), ca.SX.sym("u", NU)
        pose_next = casadi_step(x[0:3], u[0:2], dt)
        lam_next = timing_law(path, x[3], x[2], u[2], dt, CASADI)
        f = ca.Function("f", [x, u], [ca.vertcat(pose_next, lam_next, u[0], u[1])])
        e1, e2, e3, _ = path_error(path, x[0], x[1], x[2], 0.0, x[3], ego.v_ref, CASADI, wrap=False)
        pose_cost = ca.Function("pose_cost", [x], [w_c1 * e1**2 + w_c2 * e2**2 + w_th * e3**2])
        risk = None
        if variant != "free":
            ego_s, belief_s = ca.SX.sym("ego", 4), ca.SX.sym("belief", Belief.SIZE)
            eps_s, data_s = ca.SX.sym("epsilon"), ca.SX.sym("data", *self._risk_parameter_shape())
            margin = self._margin(ego_s, Belief.from_array(belief_s), eps_s, data_s, variant == "zero")
            # only the ego state is a variable: no derivatives for the rest (compiled code: less)
            risk = ca.Function(
                "risk",
                [ego_s, belief_s, eps_s, data_s],
                [margin],
                {"is_diff_in": [True, False, False, False]},
            )
        stages = {"f": f, "pose_cost": pose_cost, "risk": risk}

        # --- the NLP in SX, every stage function inlined (what the solver runs uncompiled)
        nlp, layout, belief_fn = self._assemble(ca.SX, variant, stages)
        w_tags, g_tags, lbg, ubg = layout
        p = nlp["p"]

        # --- solver
        options: dict[str, Any] = {"expand": True, "print_time": False, "error_on_fail": False}
        options.update(self._plugin_options())
        if self.solver_name == "fatrop":
            options["equality"] = [lo == hi for lo, hi in zip(lbg, ubg, strict=True)]
        jit = self.jit and have_c_compiler()
        if self.jit and not jit:
            warnings.warn("jit=True but no C compiler was found: building without jit", stacklevel=4)
        solver = ca.nlpsol("mpc", self.solver_name, nlp, options)
        if jit:
            # the same NLP in MX, the stage functions called rather than inlined: the generated C
            # code holds the risk row and its derivatives once instead of N times
            calls, *_ = self._assemble(ca.MX, variant, stages)
            compiled = self._compiled_solver(calls, {**options, "expand": False})
            jit = compiled is not None
            solver = compiled if jit else solver

        index = {tag: i for i, tag in enumerate(w_tags)}
        return _Problem(
            variant=variant,
            solver=solver,
            evaluate=ca.Function("evaluate", [nlp["x"], p], [nlp["f"], nlp["g"]]),
            rollout=f.mapaccum(N),
            beliefs=belief_fn,
            lbg=np.array(lbg),
            ubg=np.array(ubg),
            x_index=np.array([[index[(n, "x", i)] for i in range(NX)] for n in range(N + 1)]),
            u_index=np.array([[index[(n, "u", i)] for i in range(NU)] for n in range(N)]),
            risk_rows=np.array([i for i, tag in enumerate(g_tags) if tag[1] == "risk"], dtype=int),
            w_tags=tuple(w_tags),
            shift_w=np.array([index.get((s + 1, k, c), i) for i, (s, k, c) in enumerate(w_tags)]),
            g_tags=tuple(g_tags),
            build_time=time.perf_counter() - t0,
            jit=jit,
        )

    def _assemble(
        self, sym: type, variant: str, stages: dict[str, ca.Function | None]
    ) -> tuple[dict[str, Any], tuple[list, list, list, list], ca.Function]:
        """The NLP of :meth:`_build` with symbols of type ``sym`` (``ca.SX``: the stage functions
        inlined; ``ca.MX``: called), its layout ``(w_tags, g_tags, lbg, ubg)`` and the beliefs'
        function."""
        sc = self.scenario
        N, ego = sc.horizon, sc.ego
        w_v = sc.cost_weights[3]
        f, pose_cost, risk = stages["f"], stages["pose_cost"], stages["risk"]

        # --- parameters: object measurement, epsilon, the uncertainty's numbers (so that the levels
        # share one solver), per-step risk data; the object's beliefs
        p_obj = sym.sym("object", 5)
        p_eps = sym.sym("epsilon")
        p_unc = sym.sym("uncertainty", len(_uncertainty_vector(sc)))
        p_data = [sym.sym(f"risk_data_{n}", *self._risk_parameter_shape()) for n in range(1, N + 1)]
        p = ca.vertcat(p_obj, p_eps, p_unc, *(ca.vec(d) for d in p_data))
        beliefs = predict(sc, p_obj, steps=N, ops=CASADI, uncertainty=_symbolic_uncertainty(p_unc))
        fields = [f.name for f in dataclasses.fields(Belief)]
        stacked = [ca.vertcat(*(getattr(b, k) for k in fields)) for b in beliefs]
        belief_fn = ca.Function("beliefs", [p_obj, p_unc], [ca.horzcat(*stacked).T])

        # --- variables, stage by stage: x_0, u_0, x_1, u_1, ..., x_N
        X = [sym.sym(f"x_{n}", NX) for n in range(N + 1)]
        U = [sym.sym(f"u_{n}", NU) for n in range(N)]
        w: list[Any] = []
        w_tags: list[tuple[int, str, int]] = []
        g: list[Any] = []
        g_tags: list[tuple[int, str, int]] = []
        lbg: list[float] = []
        ubg: list[float] = []

        def add_g(expr: Any, lo: float, hi: float, stage: int, kind: str) -> None:
            g.append(expr)
            for i in range(expr.numel()):
                g_tags.append((stage, kind, i))
                lbg.append(lo)
                ubg.append(hi)

        def add_risk(n: int) -> None:
            if risk is None:
                return
            ego_n = ca.vertcat(X[n][0], X[n][1], X[n][2], X[n][4])  # pose of state n, speed v_{n-1}
            add_g(risk(ego_n, stacked[n], p_eps, p_data[n - 1]), 0.0, math.inf, n, "risk")

        # --- objective, dynamics, rate limits and risk, stage-wise
        cost = 0.0
        for n in range(N):
            w += [X[n], U[n]]
            w_tags += [(n, "x", i) for i in range(NX)] + [(n, "u", i) for i in range(NU)]
            add_g(X[n + 1] - f(X[n], U[n]), 0.0, 0.0, n, "gap")
            add_g(U[n][0] - X[n][4], -self._dv, self._dv, n, "rate_v")
            add_g(U[n][1] - X[n][5], -self._dw, self._dw, n, "rate_omega")
            if n >= 1:
                add_risk(n)
            cost += w_v * (U[n][2] - ego.v_ref) ** 2
            cost += pose_cost(X[n + 1] if self.stage_cost == "reached" else X[n])
        w.append(X[N])
        w_tags += [(N, "x", i) for i in range(NX)]
        add_risk(N)
        nlp = {"x": ca.vertcat(*w), "f": cost, "g": ca.vertcat(*g), "p": p}
        return nlp, (w_tags, g_tags, lbg, ubg), belief_fn

    def _compiled_solver(self, nlp: dict[str, Any], options: dict[str, Any]) -> ca.Function | None:
        """The solver of ``nlp`` with its functions (the NLP and the derivatives the solver
        evaluates) compiled into a shared library, loaded from the disk cache when it holds this
        exact NLP.

        The library is generated with :class:`casadi.CodeGenerator` and compiled by ``$CC`` (or
        gcc) at ``-O{jit_opt}`` in a private temporary directory, then moved into ``jit_cache``
        under a hash of the NLP, the CasADi version and the compiler flags, so any later process
        (or agent) with the same NLP loads it in milliseconds. Nothing is written to the working
        directory and the process never changes directory. (CasADi's own ``jit`` option, used
        before, cannot promise that: in CasADi 3.8 nlpsol's jit writes its C source to the working
        directory whatever ``jit_options["directory"]`` says, and only the object files follow
        that option.) Returns None (with a warning) when code generation, compilation or loading
        fails.
        """
        oracle = ca.Function("nlp", [nlp["x"], nlp["p"]], [nlp["f"], nlp["g"]], ["x", "p"], ["f", "g"])
        solver = ca.nlpsol("mpc", self.solver_name, oracle, options)  # for its derivative functions
        names = [n for n in _COMPILED_FUNCTIONS if solver.has_function(n)]
        compiler = os.environ.get("CC", "gcc")
        flags = [f"-O{self.jit_opt}"]
        key = [ca.__version__, compiler, " ".join(flags), " ".join(names), oracle.serialize()]
        digest = hashlib.sha256("\n".join(key).encode()).hexdigest()[:24]
        name = f"riskmpc_{digest}"
        cache = _private_cache() if self.jit_cache is None else os.fspath(self.jit_cache)
        library = os.path.join(cache, f"{name}.so")
        try:
            if not os.path.exists(library):
                os.makedirs(cache, exist_ok=True)
                with tempfile.TemporaryDirectory(prefix="riskmpc_build_") as tmp:
                    generator = ca.CodeGenerator(name, {"with_header": False})
                    generator.add(oracle)
                    for n in names:
                        generator.add(solver.get_function(n))
                    source = generator.generate(tmp + os.sep)
                    built = os.path.join(tmp, f"{name}.so")
                    subprocess.run(
                        [*shlex.split(compiler), "-fPIC", "-shared", *flags, source, "-o", built],
                        cwd=tmp,
                        check=True,
                        capture_output=True,
                    )
                    partial = f"{library}.{os.getpid()}.tmp"
                    shutil.move(built, partial)
                    os.replace(partial, library)  # atomic: no process loads a half-written library
            # the oracle is the library's compiled "nlp": nothing left to expand
            loaded = {k: v for k, v in options.items() if k != "expand"}
            return ca.nlpsol("mpc", self.solver_name, library, loaded)
        except Exception as err:  # a broken compiler must not break the agent
            detail = (getattr(err, "stderr", None) or b"").decode(errors="replace")[:300]
            warnings.warn(f"compiling the solver failed ({err} {detail}); building without jit", stacklevel=5)
            return None

    # ------------------------------------------------------------------ one step
    def _measured_state(self, o: ob.Observation) -> np.ndarray:
        """x_0: the pose with theta unwrapped near theta_P(lambda_k), lambda_k, the last input."""
        lam = o.progress
        theta_p = float(point(self.scenario.path, lam)[2])
        theta = theta_p + float(NUMPY.wrap_angle(o.ego_pose[2] - theta_p))
        return np.array([o.ego_pose[0], o.ego_pose[1], theta, lam, o.ego_input[0], o.ego_input[1]])

    def _rollout(self, pr: _Problem, x0: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """States ``(N+1, NX)`` under inputs ``(N, NU)``: the model f of the NLP."""
        return np.vstack([x0, np.asarray(pr.rollout(x0, inputs.T)).T])

    def _pack(self, pr: _Problem, states: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        w = np.zeros(pr.n_w)
        w[pr.x_index] = states
        w[pr.u_index] = inputs
        return w

    def _ramp(self, start: float, target: float, rate: float, limit: tuple[float, float]) -> np.ndarray:
        """N values moving from ``start`` toward ``target`` by at most ``rate`` per step."""
        out, value = [], start
        for _ in range(self.horizon):
            value = float(np.clip(np.clip(target, value - rate, value + rate), *limit))
            out.append(value)
        return np.array(out)

    def _candidates(self, x0: np.ndarray) -> dict[str, np.ndarray]:
        """Input sequences ``(N, NU)`` for a cold start: brake, track the path, reverse."""
        ego, dt, path = self.scenario.ego, self.scenario.dt, self.scenario.path
        v_lim, w_lim = (ego.v_min, ego.v_max), (-ego.omega_max, ego.omega_max)
        out = {}
        for name, v_target in (("brake", 0.0), ("track", ego.v_ref), ("reverse", ego.v_min)):
            v = self._ramp(x0[4], v_target, self._dv, v_lim)
            if name == "track":  # pure pursuit of the path point a few metres ahead
                omega, pose, lam, w_prev = [], x0[:3], x0[3], x0[5]
                for vn in v:
                    px, py, _ = point(path, lam + max(4.0, 2.0 * abs(vn)))
                    bearing = math.atan2(py - pose[1], px - pose[0])
                    desired = 1.5 * float(NUMPY.wrap_angle(bearing - pose[2]))
                    w_prev = float(np.clip(np.clip(desired, w_prev - self._dw, w_prev + self._dw), *w_lim))
                    omega.append(w_prev)
                    lam = timing_law(path, lam, pose[2], vn, dt)
                    half = 0.5 * w_prev * dt
                    arc = vn * dt * float(NUMPY.sinc(half))
                    pose = np.array(
                        [
                            pose[0] + arc * math.cos(pose[2] + half),
                            pose[1] + arc * math.sin(pose[2] + half),
                            pose[2] + w_prev * dt,
                        ]
                    )
                omega = np.array(omega)
            else:
                omega = self._ramp(x0[5], 0.0, self._dw, w_lim)
            out[name] = np.column_stack([v, omega, np.clip(v, *v_lim)])
        return out

    def _cold_guesses(self, pr: _Problem, x0: np.ndarray, p: np.ndarray, lbg: np.ndarray) -> list[np.ndarray]:
        """The candidate rollouts packed as w, best first: smallest constraint violation, then cost."""
        scored = []
        for inputs in self._candidates(x0).values():
            w0 = self._pack(pr, self._rollout(pr, x0, inputs), inputs)
            cost, g = pr.evaluate(w0, p)
            g = np.asarray(g).ravel()
            violation = np.sum(np.maximum(lbg - g, 0.0) + np.maximum(g - pr.ubg, 0.0))
            scored.append((float(violation), float(cost), len(scored), w0))
        return [w0 for *_, w0 in sorted(scored, key=lambda s: s[:3])]

    def _bounds(self, pr: _Problem, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ego = self.scenario.ego
        lbx, ubx = np.full(pr.n_w, -np.inf), np.full(pr.n_w, np.inf)
        lbx[pr.x_index[0]] = ubx[pr.x_index[0]] = x0
        lbx[pr.x_index[1:, 3]] = min(self.scenario.path.lambda_start, x0[3])
        lbx[pr.u_index] = (ego.v_min, -ego.omega_max, ego.v_min)
        ubx[pr.u_index] = (ego.v_max, ego.omega_max, ego.v_max)
        return lbx, ubx

    def _reach(self, v_last: float) -> np.ndarray:
        """Upper bound [m] on the distance from the current position to the state n = 1..N."""
        speeds = np.minimum(self._speed_cap, abs(v_last) + self._dv * np.arange(1, self.horizon + 1))
        return np.cumsum(speeds) * self.scenario.dt

    def _risk_possible(self, x0: np.ndarray, future: Belief) -> bool:
        """Whether some step's risk could be nonzero where the ego can reach (else: ``"free"``)."""
        distance = signed_box_distance(x0[0] - future.x, x0[1] - future.y, future.half_x, future.half_y)
        spare = distance - self._reach(x0[4]) - self.scenario.collision_distance
        return bool(np.any(spare <= FREE_MARGIN))

    def _g_map(self, old: _Problem, new: _Problem) -> np.ndarray:
        """For each row of ``new``, the row of ``old`` one stage later (-1: none)."""
        key = (old.variant, new.variant)
        if key not in self._g_maps:
            where = {tag: i for i, tag in enumerate(old.g_tags)}
            self._g_maps[key] = np.array(
                [where.get((s + 1, k, c), where.get((s, k, c), -1)) for s, k, c in new.g_tags], dtype=int
            )
        return self._g_maps[key]

    def _warm_guess(
        self, pr: _Problem, mem: dict[str, Any], x0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The previous solution shifted by one stage, states re-simulated from ``x0``."""
        prev_inputs = mem["w"][pr.u_index]
        shifted = np.vstack([prev_inputs[1:], prev_inputs[-1:]])
        w0 = self._pack(pr, self._rollout(pr, x0, shifted), shifted)
        if not self.warm_start or self.solver_name != "ipopt":
            return w0, None, None
        old = self._problems[mem["variant"]]
        g_map = self._g_map(old, pr)
        lam_g = np.where(g_map >= 0, mem["lam_g"][np.maximum(g_map, 0)], 0.0)
        return w0, mem["lam_x"][pr.shift_w], lam_g

    def _call(self, pr: _Problem, args: dict[str, Any]) -> tuple[dict[str, np.ndarray], str, bool, int, dict]:
        try:
            with np.errstate(all="ignore"):
                res = pr.solver(**args)
            stats = pr.solver.stats()
        except Exception as err:  # never raise inside an episode
            return {}, f"exception: {err}", False, 0, {}
        out = {k: np.asarray(v).ravel() for k, v in res.items()}
        if self.solver_name == "ipopt":
            status = str(stats.get("return_status", "unknown"))
            ok = status in IPOPT_SUCCESS
        else:
            status = str(stats.get("unified_return_status", stats.get("return_status", "unknown")))
            ok = bool(stats.get("success", False))
        ok = ok and all(np.all(np.isfinite(out[k])) for k in ("x", "lam_x", "lam_g", "f"))
        times = {k: float(v) for k, v in stats.items() if k.startswith("t_wall_") and v}
        return out, status, ok, int(stats.get("iter_count", 0)), times

    def _step(self, index: int, obs_vec: np.ndarray) -> SolveReport:
        t_start = time.perf_counter()
        o = ob.split(obs_vec)
        sc = self.scenario
        mem = self._memory.get(index)
        if mem is not None and self._new_episode(mem, o):
            mem = None
        x0 = self._measured_state(o)
        base = self._problem("free")
        uncertainty = _uncertainty_vector(sc)
        future = Belief.from_array(np.asarray(base.beliefs(o.object_measurement, uncertainty))[1:])
        variant = self._risk_variant() if self._risk_possible(x0, future) else "free"
        pr = self._problem(variant)
        data = self._risk_data(future)
        p = np.concatenate(
            [o.object_measurement, [self._epsilon], uncertainty, *(d.ravel(order="F") for d in data)]
        )
        lbx, ubx = self._bounds(pr, x0)
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
            pilot = self._pack(pr, self._rollout(pr, x0, inputs), inputs)
        for attempt in range(int(warm or pilot is not None) + self.cold_starts):
            if warm and attempt == 0:
                w0, lam_x, lam_g = self._warm_guess(pr, mem, x0)
            elif pilot is not None and attempt == 0:
                w0, lam_x, lam_g = pilot, None, None
            else:
                cold = self._cold_guesses(pr, x0, p, lbg) if cold is None else cold
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
            action = self._feasible_action(inputs[0, :2], x0[4:6])
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
            plan = mem.get("plan") if mem is not None else None
            used = mem.get("used", 0) + 1 if mem is not None else 0
            if plan is not None and used < len(plan):
                fallback = "shifted_plan"
                inputs = np.vstack([plan[used:], np.repeat(plan[-1:], used, axis=0)])
                mem = {**mem, "used": used, "w": None}
            else:
                fallback = "brake"
                v = self._ramp(x0[4], 0.0, self._dv, (sc.ego.v_min, sc.ego.v_max))
                omega = self._ramp(x0[5], 0.0, self._dw, (-sc.ego.omega_max, sc.ego.omega_max))
                inputs = np.column_stack([v, omega, v])
                mem = {"w": None, "plan": None, "used": 0}
            action = self._feasible_action(inputs[0, :2], x0[4:6])
            inputs = inputs.copy()
            inputs[0, :2] = action
            states = self._rollout(pr, x0, inputs)
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

    def _feasible_action(self, action: np.ndarray, last: np.ndarray) -> np.ndarray:
        """``action`` clipped into the bounds and the rate limits around ``last`` (float32-safe)."""
        ego = self.scenario.ego
        shrink = 1.0 - 1e-6  # float32 rounding must not step over a limit
        dv, dw = self._dv * shrink, self._dw * shrink
        v = np.clip(np.clip(action[0], last[0] - dv, last[0] + dv), ego.v_min, ego.v_max)
        w = np.clip(np.clip(action[1], last[1] - dw, last[1] + dw), -ego.omega_max, ego.omega_max)
        return np.array([v, w], dtype=float)

    def _new_episode(self, mem: dict[str, Any], o: ob.Observation) -> bool:
        """The observation does not continue the episode this memory belongs to."""
        if "action" not in mem or np.max(np.abs(o.ego_input - mem["action"])) > 1e-3:
            return True
        return bool(np.hypot(*(o.ego_pose[:2] - mem["predicted"])) > 1.0)


@functools.cache
def _private_cache() -> str:
    """A per-process directory for compiled solvers when ``jit_cache=None`` (removed at exit)."""
    path = tempfile.mkdtemp(prefix="riskmpc_jit_")
    atexit.register(shutil.rmtree, path, ignore_errors=True)
    return path


_UNCERTAINTY_FIELDS = (
    ("sigma0", 3),
    ("sigma_growth", 3),
    ("box_half_width0", 2),
    ("box_growth", 3),
    ("velocity_bounds0", 2),
)


def _uncertainty_vector(scenario: Scenario) -> np.ndarray:
    """The scenario's :class:`~risk_env.scenario.Uncertainty` as the solver's parameter vector."""
    u = scenario.uncertainty
    return np.concatenate([np.asarray(getattr(u, name), float) for name, _ in _UNCERTAINTY_FIELDS])


def _symbolic_uncertainty(p: ca.SX) -> SimpleNamespace:
    """An uncertainty whose numbers are the entries of ``p`` (as :func:`_uncertainty_vector` lays
    them out), for :func:`risk_env.predict`."""
    out, i = {}, 0
    for name, length in _UNCERTAINTY_FIELDS:
        out[name] = tuple(p[i + k] for k in range(length))
        i += length
    return SimpleNamespace(**out)


def _problem_key(scenario: Scenario) -> tuple[Any, ...]:
    """What of the scenario is built into a solver: all but epsilon and the uncertainty."""
    skip = ("risk_tolerance", "uncertainty")
    return tuple(
        (f.name, getattr(scenario, f.name)) for f in dataclasses.fields(scenario) if f.name not in skip
    )
