r"""The MPC's last resort and its safety clip: a family of rate-limited manoeuvres, the choice of the
safest one, and the clip that keeps every applied action within the input bounds and rate limits.

The family (:data:`MANOEUVRES`, then :data:`FOLLOWERS`): each of four speed targets (brake to 0,
hold the current speed, accelerate to $v_{max}$, reverse to $v_{min}$) with each of three turn targets
(straight, full left, full right), every target approached as fast as the rate limits allow; and,
with a corridor about the path (``path.corridor`` finite), each speed target **following the path**
(pure pursuit of the path point a few metres ahead, :func:`agents.mpc.guesses.pursuit`): on a
curved lane no straight or full-lock member stays on the road, a path follower does.

:func:`safest` ranks them **by the corridor** first (the fewer stages the ego centre spends outside
the path's corridor, the better: on a road, leaving it is never the safe choice), then by the agent's
own risk (the longer the predicted risk stays within $\epsilon$, the safer), then by the worst-case
clearance (the distance from the ego disc to the object's truncation box) at the first step where
the risk exceeds $\epsilon$ (the less it is violated, the safer), then by the smallest clearance over
the horizon $n = 1, \dots, N$. So the MPC never brakes blindly: among the manoeuvres that keep to its
lane, braking is chosen only when no other keeps clear of the object longer, or by more. The
corridor comes first as in the soft problem, where a metre outside it costs more than any risk
slack (:mod:`agents.mpc.nlp.corridor`). Measured at the intersection with the default wall-time cap
(``python -m benchmarks.highway_intersection --episodes 5 --agents rmpc``): ranked after the
risk, the manoeuvres escaped the boxes sideways and the ego left the road in 5 of 5 episodes; ranked
first, in none. Without a corridor every manoeuvre stays "within" it, and the ranking is the risk's
and the clearance's alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from agents.mpc.guesses import pursuit, ramp
from risk_env.models.dynamics import turn_limit
from risk_env.models.path import lateral_offset
from risk_env.scenario.scenario import Scenario

SPEEDS: tuple[str, ...] = ("brake", "hold", "accelerate", "reverse")
TURNS: tuple[str, ...] = ("", "left", "right")
FOLLOW = "path"
"""The turn "target" of the family members that follow the path (only with a finite corridor)."""
MANOEUVRES: tuple[str, ...] = tuple(f"{s}_{t}" if t else s for s in SPEEDS for t in TURNS)
"""Names of the family, e.g. ``"brake"``, ``"accelerate_left"``, ``"reverse_right"``."""
FOLLOWERS: tuple[str, ...] = tuple(f"{s}_{FOLLOW}" for s in SPEEDS)
"""Names of the path followers, e.g. ``"brake_path"``: in the family after :data:`MANOEUVRES` with a
finite corridor."""


def feasible_action(scenario: Scenario, action: np.ndarray, last: np.ndarray) -> np.ndarray:
    r"""``action`` ($v$ [m/s], $\omega$ [rad/s]) clipped into the bounds and the rate limits around the
    last applied input ``last`` (2,), with a margin so that float32 rounding steps over no limit."""
    ego, dt = scenario.ego, scenario.dt
    shrink = 1.0 - 1e-6
    dv, dw = ego.accel_max * dt * shrink, ego.omega_rate_max * dt * shrink
    v = np.clip(np.clip(action[0], last[0] - dv, last[0] + dv), ego.v_min, ego.v_max)
    w = np.clip(np.clip(action[1], last[1] - dw, last[1] + dw), -ego.omega_max, ego.omega_max)
    w = turn_limit(ego.curvature_max, w, v * shrink)  # a car turns only while it moves
    return np.array([v, w], dtype=float)


def manoeuvres(scenario: Scenario, x0: np.ndarray) -> dict[str, np.ndarray]:
    r"""The family's inputs ``(N, NU)`` ($v$ [m/s], $\omega$ [rad/s], $u_2 = v$) from the state ``x0``
    ``(NX,)`` whose last applied input is ``x0[4:6]``, each within the bounds and rate limits (the
    path followers only with a finite corridor)."""
    ego, dt, N = scenario.ego, scenario.dt, scenario.horizon
    v_lim, w_lim = (ego.v_min, ego.v_max), (-ego.omega_max, ego.omega_max)
    v_last, w_last, kappa = float(x0[4]), float(x0[5]), ego.curvature_max
    speed = {"brake": 0.0, "hold": v_last, "accelerate": ego.v_max, "reverse": ego.v_min}
    turn = {"": 0.0, "left": ego.omega_max, "right": -ego.omega_max}
    out = {}
    for s in SPEEDS:
        v = ramp(v_last, speed[s], ego.accel_max * dt, v_lim, N)
        for t in TURNS:
            omega = ramp(w_last, turn[t], ego.omega_rate_max * dt, w_lim, N)
            out[f"{s}_{t}" if t else s] = np.column_stack([v, turn_limit(kappa, omega, v), v])
    if math.isfinite(scenario.path.corridor):
        for s in SPEEDS:
            v = ramp(v_last, speed[s], ego.accel_max * dt, v_lim, N)
            out[f"{s}_{FOLLOW}"] = np.column_stack([v, turn_limit(kappa, pursuit(scenario, x0, v), v), v])
    return out


def safest(risk: np.ndarray, clearance: np.ndarray, epsilon: float, outside: np.ndarray | None = None) -> int:
    r"""Index of the safest manoeuvre: risk ``(M, N)`` by the agent's own estimator and worst-case
    clearance ``(M, N)`` [m] at the states $n = 1, \dots, N$; ``outside`` ``(M, N)``: whether state $n$ lies
    outside the corridor (None: none does). Ranked by the number of stages outside the corridor (fewer
    is better), then by the first step whose risk exceeds $\epsilon$ (later is safer; never is safest),
    then by the clearance at the risk's first step, then by the smallest clearance over n (larger is safer);
    ties go to the earlier manoeuvre of the family."""
    risk, clearance = np.asarray(risk, float), np.asarray(clearance, float)
    if risk.shape != clearance.shape or risk.ndim != 2 or risk.shape[0] == 0:
        raise ValueError(f"risk and clearance must be (M, N), M >= 1, got {risk.shape}, {clearance.shape}")
    outside = np.zeros(risk.shape, bool) if outside is None else np.asarray(outside, bool)
    if outside.shape != risk.shape:
        raise ValueError(f"outside must be (M, N) as the risk, {risk.shape}, got {outside.shape}")
    clearance = np.nan_to_num(clearance, nan=-np.inf)
    exceeds = ~(risk <= epsilon * (1.0 + 1e-9) + 1e-9)  # NaN counts as exceeding
    first = np.where(exceeds.any(axis=1), exceeds.argmax(axis=1), risk.shape[1])
    leaves = risk.shape[1] - outside.sum(axis=1)  # stages inside
    rows = np.arange(len(risk))
    at_first = np.where(first < risk.shape[1], clearance[rows, np.minimum(first, risk.shape[1] - 1)], np.inf)
    return int(np.lexsort((-clearance.min(axis=1), -at_first, -first, -leaves))[0])


def choose(
    scenario: Scenario,
    x0: np.ndarray,
    rollout: Callable[[np.ndarray], np.ndarray],
    risk: Callable[[np.ndarray], np.ndarray],
    worsts: Sequence[object],
    futures: Sequence[object | None],
    epsilon: float,
) -> tuple[str, np.ndarray]:
    r"""``(name, inputs (N, NU))`` of the :func:`safest` manoeuvre from the state ``x0`` ``(NX,)``:
    ``rollout(inputs)`` gives the states ``(N+1, NX)`` from it, ``risk(ego (N, 4))`` the agent's own risk
    ``(N,)`` over the present objects, ``worsts[k]`` slot k's worst-case estimator (the clearance to
    the nearest truncation box of ``futures[k]``, the slot's beliefs or None); the corridor: the
    path's."""
    family = manoeuvres(scenario, x0)
    states = np.stack([rollout(u)[1:] for u in family.values()])
    ego = states[:, :, [0, 1, 2, 4]]  # pose of state n with the speed v_{n-1} that led there
    risks = np.stack([np.asarray(risk(e), float).reshape(-1) for e in ego])
    clearance = np.full(risks.shape, np.inf)
    for k, f in enumerate(futures):
        if f is not None:
            worst = worsts[k]
            clearance = np.minimum(clearance, worst.distance(ego, f) - worst.radius)
    outside, corridor = None, scenario.path.corridor
    if math.isfinite(corridor):
        outside = np.abs(lateral_offset(scenario.path, states[..., 0], states[..., 1])) > corridor
    name = list(family)[safest(risks, clearance, epsilon, outside)]
    return name, family[name]
