"""The one interface of the collision-risk estimators, :class:`RiskEstimator`, and the helpers they
share (:mod:`risk_env.risk` names the estimators)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import casadi as ca
import numpy as np

from risk_env.models.ops import CASADI, NUMPY, Ops
from risk_env.prediction.belief import Belief
from risk_env.risk.quadrature import GEOMETRY_FLOOR
from risk_env.risk.severity import Severity, make_severity
from risk_env.scenario.scenario import Scenario

EgoFloats = tuple[float, float, float, float]
"""One ego state ``(c1 [m], c2 [m], theta [rad], v [m/s])`` as Python floats."""


def ego_parts(ego: Any) -> tuple[Any, Any, Any, Any]:
    """``(c1 [m], c2 [m], theta [rad], v [m/s])`` of ego states ``(..., 4)`` (numpy), a CasADi
    vector of 4 or a sequence of 4 floats."""
    if isinstance(ego, np.ndarray):
        if ego.shape[-1:] != (4,):
            raise ValueError(f"ego state must have a last axis of 4 (c1, c2, theta, v), got {ego.shape}")
        return ego[..., 0], ego[..., 1], ego[..., 2], ego[..., 3]
    return ego[0], ego[1], ego[2], ego[3]


def shape_of(a: Any) -> tuple[int, ...]:
    """``np.shape(a)``, without its array conversion for floats and arrays."""
    if isinstance(a, float):
        return ()
    return a.shape if isinstance(a, np.ndarray) else np.shape(a)


def floor_geometry(a: Any) -> Any:
    """``a`` raised to :data:`GEOMETRY_FLOOR`; Python floats stay floats."""
    return max(a, GEOMETRY_FLOOR) if isinstance(a, (float, int)) else np.maximum(a, GEOMETRY_FLOOR)


class RiskEstimator(ABC):
    """R_{n|k} for ego states against the object's belief at the same prediction step.

    ``risk`` is the numpy form (batched by broadcasting); ``casadi_risk`` the symbolic one;
    ``casadi_margin(ego, belief, epsilon)`` is >= 0 exactly when R <= epsilon, scaled for a solver.
    """

    name: str
    smooth: bool = True
    """Whether the CasADi form has useful gradients everywhere (False: piecewise smooth)."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.severity: Severity = make_severity(scenario)
        self.radius = scenario.collision_distance

    @abstractmethod
    def _risk(self, ego: Any, belief: Belief, ops: Ops, **kwargs: Any) -> Any: ...

    def risk(self, ego: np.ndarray, belief: Belief, rng: np.random.Generator | None = None) -> np.ndarray:
        """R for ``ego (..., 4)`` states: shape ``(...)`` broadcast with the belief's fields."""
        return np.asarray(self._risk(np.asarray(ego, dtype=float), belief, NUMPY))

    def risk_one(self, ego: EgoFloats, belief: Belief, rng: np.random.Generator | None = None) -> float:
        """R for one ego state ``(c1, c2, theta, v)`` of floats against a belief of floats, as a
        float: :meth:`risk`'s value, without its array round trip where the estimator has a
        scalar form (the single env's step)."""
        return float(self.risk(np.array(ego, dtype=float), belief, rng=rng))

    def casadi_risk(self, ego: ca.SX, belief: Belief, **kwargs: Any) -> ca.SX:
        """The symbolic R for a CasADi ego vector of 4 and a belief of CasADi scalars."""
        return self._risk(ego, belief, CASADI, **kwargs)

    def casadi_margin(self, ego: ca.SX, belief: Belief, epsilon: float | ca.SX, **kwargs: Any) -> ca.SX:
        """``(epsilon - R) / scale``: >= 0 when the constraint R <= epsilon holds."""
        return (epsilon - self.casadi_risk(ego, belief, **kwargs)) / self.severity.scale

    def __repr__(self) -> str:
        return f"{type(self).__name__}(severity={self.severity.name!r})"
