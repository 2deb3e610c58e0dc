r"""The MPC's last resort and its safety clip: a family of rate-limited manoeuvres, the choice of the
safest one, and the clip that keeps every applied action within the input bounds and rate limits.

The family (:data:`MANOEUVRES`): each of four speed targets (brake to 0, hold the current speed,
accelerate to $v_{max}$, reverse to $v_{min}$) with each of three turn targets (straight, full left, full
right), every target approached as fast as the rate limits allow. :func:`safest` ranks them by
the agent's own risk first (the longer the predicted risk stays within $\epsilon$, the safer), then
by the worst-case clearance (the distance from the ego disc to the object's truncation box) at the
first step where the risk exceeds $\epsilon$ (the less it is violated, the safer), then by the
smallest clearance over the horizon $n = 1, \dots, N$. So the MPC never brakes blindly: braking is chosen
only when no other manoeuvre keeps clear of the object longer, or by more.
"""

from __future__ import annotations

import numpy as np

from agents.mpc.guesses import ramp
from risk_env.scenario.scenario import Scenario

SPEEDS: tuple[str, ...] = ("brake", "hold", "accelerate", "reverse")
TURNS: tuple[str, ...] = ("", "left", "right")
MANOEUVRES: tuple[str, ...] = tuple(f"{s}_{t}" if t else s for s in SPEEDS for t in TURNS)
"""Names of the family, e.g. ``"brake"``, ``"accelerate_left"``, ``"reverse_right"``."""


def feasible_action(scenario: Scenario, action: np.ndarray, last: np.ndarray) -> np.ndarray:
    r"""``action`` ($v$ [m/s], $\omega$ [rad/s]) clipped into the bounds and the rate limits around the
    last applied input ``last`` (2,), with a margin so that float32 rounding steps over no limit."""
    ego, dt = scenario.ego, scenario.dt
    shrink = 1.0 - 1e-6
    dv, dw = ego.accel_max * dt * shrink, ego.omega_rate_max * dt * shrink
    v = np.clip(np.clip(action[0], last[0] - dv, last[0] + dv), ego.v_min, ego.v_max)
    w = np.clip(np.clip(action[1], last[1] - dw, last[1] + dw), -ego.omega_max, ego.omega_max)
    return np.array([v, w], dtype=float)


def manoeuvres(scenario: Scenario, x0: np.ndarray) -> dict[str, np.ndarray]:
    r"""The family's inputs ``(N, NU)`` ($v$ [m/s], $\omega$ [rad/s], $u_2 = v$) from the state ``x0``
    ``(NX,)`` whose last applied input is ``x0[4:6]``, each within the bounds and rate limits."""
    ego, dt, N = scenario.ego, scenario.dt, scenario.horizon
    v_lim, w_lim = (ego.v_min, ego.v_max), (-ego.omega_max, ego.omega_max)
    v_last, w_last = float(x0[4]), float(x0[5])
    speed = {"brake": 0.0, "hold": v_last, "accelerate": ego.v_max, "reverse": ego.v_min}
    turn = {"": 0.0, "left": ego.omega_max, "right": -ego.omega_max}
    out = {}
    for s in SPEEDS:
        v = ramp(v_last, speed[s], ego.accel_max * dt, v_lim, N)
        for t in TURNS:
            omega = ramp(w_last, turn[t], ego.omega_rate_max * dt, w_lim, N)
            out[f"{s}_{t}" if t else s] = np.column_stack([v, omega, v])
    return out


def safest(risk: np.ndarray, clearance: np.ndarray, epsilon: float) -> int:
    r"""Index of the safest manoeuvre: risk ``(M, N)`` by the agent's own estimator and worst-case
    clearance ``(M, N)`` [m] at the states $n = 1, \dots, N$. Ranked by the first step whose risk exceeds
    $\epsilon$ (later is safer; never is safest), then by the clearance at that step, then by the
    smallest clearance over n (larger is safer); ties go to the earlier manoeuvre of the family."""
    risk, clearance = np.asarray(risk, float), np.asarray(clearance, float)
    if risk.shape != clearance.shape or risk.ndim != 2 or risk.shape[0] == 0:
        raise ValueError(f"risk and clearance must be (M, N), M >= 1, got {risk.shape}, {clearance.shape}")
    clearance = np.nan_to_num(clearance, nan=-np.inf)
    exceeds = ~(risk <= epsilon * (1.0 + 1e-9) + 1e-9)  # NaN counts as exceeding
    first = np.where(exceeds.any(axis=1), exceeds.argmax(axis=1), risk.shape[1])
    rows = np.arange(len(risk))
    at_first = np.where(first < risk.shape[1], clearance[rows, np.minimum(first, risk.shape[1] - 1)], np.inf)
    return int(np.lexsort((-clearance.min(axis=1), -at_first, -first))[0])
