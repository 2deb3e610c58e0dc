"""What the MPC applies when no solve succeeds, and the clip that keeps every applied action within
the input bounds and rate limits."""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.guesses import ramp
from risk_env.scenario import Scenario


def feasible_action(scenario: Scenario, action: np.ndarray, last: np.ndarray) -> np.ndarray:
    """``action`` (v [m/s], omega [rad/s]) clipped into the bounds and the rate limits around the
    last applied input ``last`` (2,), with a margin so that float32 rounding steps over no limit."""
    ego, dt = scenario.ego, scenario.dt
    shrink = 1.0 - 1e-6
    dv, dw = ego.accel_max * dt * shrink, ego.omega_rate_max * dt * shrink
    v = np.clip(np.clip(action[0], last[0] - dv, last[0] + dv), ego.v_min, ego.v_max)
    w = np.clip(np.clip(action[1], last[1] - dw, last[1] + dw), -ego.omega_max, ego.omega_max)
    return np.array([v, w], dtype=float)


def fallback_plan(
    scenario: Scenario, x0: np.ndarray, memory: dict[str, Any] | None
) -> tuple[str, np.ndarray, dict[str, Any]]:
    """``(kind, inputs (N, NU), memory)`` after a failed step from state ``x0`` (NX,): the next
    input of the last successful plan while one is left (``"shifted_plan"``), else v and omega
    toward 0 as fast as the rate limits allow (``"brake"``)."""
    plan = memory.get("plan") if memory is not None else None
    used = memory.get("used", 0) + 1 if memory is not None else 0
    if plan is not None and used < len(plan):
        inputs = np.vstack([plan[used:], np.repeat(plan[-1:], used, axis=0)])
        return "shifted_plan", inputs, {**memory, "used": used, "w": None}
    ego, dt, N = scenario.ego, scenario.dt, scenario.horizon
    v = ramp(x0[4], 0.0, ego.accel_max * dt, (ego.v_min, ego.v_max), N)
    omega = ramp(x0[5], 0.0, ego.omega_rate_max * dt, (-ego.omega_max, ego.omega_max), N)
    return "brake", np.column_stack([v, omega, v]), {"w": None, "plan": None, "used": 0}
