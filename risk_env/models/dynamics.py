r"""The unicycle with the paper's exact arc update (Sec. VI-A), written once for both backends.

$c_1^+ = c_1 + (v / \omega)(\sin(\theta + \omega T) - \sin \theta)$ and so on divides by $\omega$;
the form used here, $v T \,\mathrm{sinc}(\omega T / 2) \cos(\theta + \omega T / 2)$, is the same map
and stays smooth and exact as $\omega \to 0$ (a straight line).
"""

from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np

from risk_env.models.ops import CASADI, NUMPY, Ops


def unicycle_step(
    x: Any, y: Any, theta: Any, v: Any, omega: Any, dt: float | Any, ops: Ops
) -> tuple[Any, Any, Any]:
    """One step of length ``dt`` [s] at constant ``(v [m/s], omega [rad/s])``; positions [m]."""
    half = 0.5 * omega * dt
    arc = v * dt * ops.sinc(half)
    mid = theta + half
    return x + arc * ops.cos(mid), y + arc * ops.sin(mid), theta + omega * dt


def step(state: np.ndarray, action: np.ndarray, dt: float) -> np.ndarray:
    """numpy face: ``state (..., 3)`` = (c1 [m], c2 [m], theta [rad]), ``action (..., 2)`` = (v, omega)."""
    state = np.asarray(state, dtype=float)
    action = np.asarray(action, dtype=float)
    out = unicycle_step(
        state[..., 0], state[..., 1], state[..., 2], action[..., 0], action[..., 1], dt, NUMPY
    )
    return np.stack(out, axis=-1)


def rollout(state: np.ndarray, action: np.ndarray, dt: float, steps: int) -> np.ndarray:
    """States under a constant action: ``(steps + 1, ..., 3)``, the first being ``state``."""
    out = [np.asarray(state, dtype=float)]
    for _ in range(steps):
        out.append(step(out[-1], action, dt))
    return np.stack(out)


def casadi_step(state: ca.SX | ca.MX, action: ca.SX | ca.MX, dt: float) -> ca.SX | ca.MX:
    """CasADi face: ``state (3,)`` and ``action (2,)`` column vectors -> next state ``(3,)``."""
    return ca.vertcat(*unicycle_step(state[0], state[1], state[2], action[0], action[1], dt, CASADI))


def turn_limit(curvature_max: float, omega: Any, v: Any) -> Any:
    r"""Turn rates ``omega`` [rad/s] within $|\omega| \le \kappa_{max} \max(v, 0)$ at the speeds ``v``
    [m/s], $\kappa_{max}$ = ``curvature_max`` [1/m] (:attr:`risk_env.scenario.parts.Ego.curvature_max`):
    a car turns only while it moves. Unchanged when $\kappa_{max}$ is infinite (the paper's unicycle)."""
    if not math.isfinite(curvature_max):  # a scalar: math's test, not numpy's, on the env's hot path
        return omega
    bound = curvature_max * np.maximum(v, 0.0)
    return np.clip(omega, -bound, bound)
