"""How the MPC's NLP is solved: the solver, its tolerances and limits, its options per rung.

:class:`SolverSettings` is what :mod:`agents.mpc.nlp.solver` builds a problem with; its
:meth:`~SolverSettings.key` is the part that changes a built solver.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

from agents.mpc.nlp.compiled import DEFAULT_JIT_CACHE
from agents.mpc.nlp.ocp import STAGE_COSTS
from risk_env import checks

SOLVERS: tuple[str, ...] = ("fatrop", "ipopt")
"""The NLP solvers (CasADi nlpsol plugins)."""


@dataclass(frozen=True)
class SolverSettings:
    """How the NLP is solved; see :class:`agents.PathFollowingMPC` for each field."""

    solver: str = "fatrop"
    stage_cost: str = "reached"
    jit: bool = False
    jit_opt: int = 1
    jit_cache: str | os.PathLike[str] | None = DEFAULT_JIT_CACHE
    tol: float = 1e-4
    max_iter: int = 150
    warm_start: bool = True
    restart_standing: bool = False
    solver_options: dict[str, Any] = field(default_factory=dict)
    time_limit: float | None = None
    """The wall-time cap of a step [s] (None: none): IPOPT's own ``max_wall_time`` at the largest
    rung; for fatrop (no time limit) it decides which rungs are worth building."""
    rungs: int = 1
    """Rungs of the ladder: rung r limits a call to ``max_iter // 2**r`` iterations (fatrop) or
    ``time_limit / 2**r`` seconds (IPOPT), so that a call fits the time left in a step."""
    soft_penalty: float = 1e4
    r"""$\rho$ of the soft variants' exact L1 penalty $\sum_n \rho\, q^{N - n} s_n$ ($q$ =
    ``EARLY_WEIGHT``) [cost per margin unit] (:mod:`agents.mpc.nlp.ocp`)."""

    def __post_init__(self) -> None:
        if self.solver not in SOLVERS:
            raise ValueError(f"unknown solver {self.solver!r}; expected one of {SOLVERS}")
        if self.stage_cost not in STAGE_COSTS:
            raise ValueError(f"unknown stage_cost {self.stage_cost!r}; expected one of {STAGE_COSTS}")
        # numbers of any real type (numpy's too), stored as Python's
        object.__setattr__(self, "max_iter", checks.integer("max_iter", self.max_iter, minimum=1))
        object.__setattr__(self, "tol", checks.positive("tol", self.tol))
        object.__setattr__(self, "rungs", checks.integer("rungs", self.rungs, minimum=1))
        if self.time_limit is not None:
            limit = checks.real("time_limit", self.time_limit)
            if not limit > 0:
                raise ValueError(f"time_limit must be > 0 [s] (or None), got {self.time_limit!r}")
            object.__setattr__(self, "time_limit", limit)
        object.__setattr__(self, "soft_penalty", checks.positive("soft_penalty", self.soft_penalty))

    def key(self) -> tuple[Any, ...]:
        """What of the settings changes a built solver (not where compiled code is kept)."""
        options = repr(sorted(self.solver_options.items()))
        return (
            self.solver,
            self.stage_cost,
            self.jit,
            self.jit_opt,
            self.tol,
            self.max_iter,
            self.warm_start,
            options,
            self.time_limit,
            self.rungs,
            self.soft_penalty,
        )

    def rung_limits(self) -> tuple[tuple[int, float | None], ...]:
        """``(max_iter, max_wall_time [s] or None)`` of each rung, the largest first."""
        out = []
        for r in range(self.rungs):
            iterations = max(1, self.max_iter >> r) if self.solver == "fatrop" else self.max_iter
            wall = None if self.time_limit is None or self.solver != "ipopt" else self.time_limit / 2**r
            out.append((iterations, wall))
        return tuple(out)

    def plugin_options(self, rung: int = 0) -> dict[str, Any]:
        """The nlpsol plugin's options (IPOPT's or fatrop's) at ``rung``, the user's on top."""
        max_iter, wall = self.rung_limits()[rung]
        extra = {k: v for k, v in self.solver_options.items() if k not in SOLVERS}
        if self.solver == "ipopt":
            ipopt = {
                "print_level": 0,
                "sb": "yes",
                "tol": self.tol,
                "constr_viol_tol": 1e-6,
                "acceptable_tol": max(1e-3, 10 * self.tol),
                "acceptable_constr_viol_tol": 1e-5,
                "acceptable_iter": 5,
                "max_iter": max_iter,
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
            if wall is not None:
                ipopt["max_wall_time"] = wall
            ipopt.update(self.solver_options.get("ipopt", {}))
            return {"ipopt": ipopt, **extra}
        # CasADi 3.8's fatrop takes a primal initial guess only (no warm_start_* options); a small
        # initial barrier and bound push suit that guess, the shifted previous solution
        fatrop = {
            "print_level": 0,
            "tol": self.tol,
            "constr_viol_tol": 1e-6,
            "max_iter": max_iter,
            "mu_init": 1e-3 if self.warm_start else 1e-1,
            "bound_push": 1e-6 if self.warm_start else 1e-2,
            "bound_frac": 1e-6 if self.warm_start else 1e-2,
        }
        fatrop.update(self.solver_options.get("fatrop", {}))
        return {"structure_detection": "auto", "fatrop": fatrop, **extra}
