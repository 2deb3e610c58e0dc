"""Initial guesses for the MPC's solver: rate-limited input ramps, simulated rollouts, and the
cold-start candidates (brake, track the path, reverse), scored on the NLP itself. A soft variant's
guess starts its slacks where the rollout misses the risk rows (and the corridor)."""

from __future__ import annotations

import math

import numpy as np

from agents.mpc.nlp import corridor
from agents.mpc.nlp.solver import Problem
from risk_env.models.ops import NUMPY
from risk_env.models.path import point, timing_law
from risk_env.scenario.scenario import Scenario


def rollout(problem: Problem, x0: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """States ``(N+1, NX)`` from ``x0`` under inputs ``(N, NU)``: the model f of the NLP."""
    return np.vstack([x0, np.asarray(problem.rollout(x0, inputs.T)).T])


def pack(problem: Problem, states: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """States ``(N+1, NX)`` and inputs ``(N, NU)`` laid out as the NLP's variables w ``(n_w,)``."""
    w = np.zeros(problem.n_w)
    w[problem.x_index] = states
    w[problem.u_index] = inputs
    return w


def fill_accumulators(problem: Problem, w: np.ndarray, p: np.ndarray) -> np.ndarray:
    r"""``w`` with the budget's accumulators $c_n = \nu (R_1 + \dots + R_{n-1})$ of its plan at
    parameters ``p`` (a no-op without a budget): with $c = 0$ the accumulator rows are $-\nu R_n$."""
    if not problem.acc_index.size:
        return w
    w = w.copy()
    w[problem.acc_index] = 0.0
    g = np.asarray(problem.evaluate(w, p)[1]).ravel()
    w[problem.acc_index] = np.cumsum(-g[problem.acc_rows])
    return w


def ramp(start: float, target: float, rate: float, limit: tuple[float, float], steps: int) -> np.ndarray:
    """``steps`` values moving from ``start`` toward ``target`` by at most ``rate`` per step, within
    ``limit``."""
    out, value = [], start
    for _ in range(steps):
        value = float(np.clip(np.clip(target, value - rate, value + rate), *limit))
        out.append(value)
    return np.array(out)


def pursuit(scenario: Scenario, x0: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Turn rates ``(N,)`` [rad/s] that follow the path from the state ``x0`` ``(NX,)`` at the
    speeds ``v`` ``(N,)`` [m/s]: pure pursuit of the path point a few metres ahead, within the
    turn-rate bounds and rate limits."""
    ego, dt, path = scenario.ego, scenario.dt, scenario.path
    dw, w_lim = ego.omega_rate_max * dt, (-ego.omega_max, ego.omega_max)
    omega, pose, lam, w_prev = [], x0[:3], x0[3], x0[5]
    for vn in v:
        px, py, _ = point(path, lam + max(4.0, 2.0 * abs(vn)))
        bearing = math.atan2(py - pose[1], px - pose[0])
        desired = 1.5 * float(NUMPY.wrap_angle(bearing - pose[2]))
        w_prev = float(np.clip(np.clip(desired, w_prev - dw, w_prev + dw), *w_lim))
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
    return np.array(omega)


def candidates(scenario: Scenario, x0: np.ndarray) -> dict[str, np.ndarray]:
    """Input sequences ``(N, NU)`` for a cold start from state ``x0`` ``(NX,)``: brake, track the
    path (pure pursuit), reverse; each within the bounds and rate limits."""
    ego, dt, N = scenario.ego, scenario.dt, scenario.horizon
    dv, dw = ego.accel_max * dt, ego.omega_rate_max * dt
    v_lim, w_lim = (ego.v_min, ego.v_max), (-ego.omega_max, ego.omega_max)
    out = {}
    for name, v_target in (("brake", 0.0), ("track", ego.v_ref), ("reverse", ego.v_min)):
        v = ramp(x0[4], v_target, dv, v_lim, N)
        if name == "track":
            omega = pursuit(scenario, x0, v)
        else:
            omega = ramp(x0[5], 0.0, dw, w_lim, N)
        out[name] = np.column_stack([v, omega, np.clip(v, *v_lim)])
    return out


SLACK_PUSH = 1e-3
"""A soft guess's slacks sit this far [margin units] above the rows' shortfall (inside s > 0)."""


def initial_point(
    problem: Problem, x0: np.ndarray, inputs: np.ndarray, p: np.ndarray, lbg: np.ndarray
) -> tuple[np.ndarray, float, float]:
    """``(w, violation, cost)``: the rollout of ``inputs`` ``(N, NU)`` from ``x0`` packed as w (a
    soft variant's slacks set to the risk rows' shortfall, so that its rows hold), the constraint
    violation of w against ``lbg`` and the problem's ubg at parameters ``p``, and the objective (a
    soft variant: with the slacks' cost, so that guesses rank as the soft problem does, early
    violations first)."""
    w = fill_accumulators(problem, pack(problem, rollout(problem, x0, inputs), inputs), p)
    cost, g = problem.evaluate(w, p)
    cost, g = float(cost), np.asarray(g).ravel()
    if problem.slack_index.size:  # the slacks where the rows fall short
        # a slack may be shared by several rows (a stage's, one per object slot): their largest
        shortfall = np.maximum(lbg[problem.risk_rows] - g[problem.risk_rows], 0.0)
        per_slack = np.zeros(problem.slack_index.size)
        np.maximum.at(per_slack, problem.row_slack, shortfall)
        w[problem.slack_index] = per_slack + SLACK_PUSH
        g[problem.risk_rows] += per_slack[problem.row_slack] + SLACK_PUSH
    ubg = corridor.fill_slacks(problem, w, g, lbg, SLACK_PUSH)  # and the corridor's
    if problem.slack_index.size:
        cost = float(problem.evaluate(w, p)[0])
    violation = float(np.sum(np.maximum(lbg - g, 0.0) + np.maximum(g - ubg, 0.0)))
    return w, violation, cost


def cold_guesses(
    problem: Problem,
    scenario: Scenario,
    x0: np.ndarray,
    p: np.ndarray,
    lbg: np.ndarray,
    extra: dict[str, np.ndarray] | None = None,
) -> list[tuple[np.ndarray, float]]:
    """The :func:`candidates` (and the ``extra`` input sequences ``(N, NU)``) as initial points w
    (:func:`initial_point`) with their constraint violations, best first: smallest violation, then
    cost."""
    scored = []
    for inputs in [*candidates(scenario, x0).values(), *(extra or {}).values()]:
        w0, violation, cost = initial_point(problem, x0, inputs, p, lbg)
        scored.append((violation, cost, len(scored), w0))
    return [(w0, violation) for violation, _, _, w0 in sorted(scored, key=lambda s: s[:3])]
