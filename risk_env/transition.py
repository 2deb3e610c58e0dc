"""The env's transition as pure functions, shared by :class:`~risk_env.env.RiskCrossingEnv` (Python
floats, the :data:`~risk_env.ops.MATH` face) and :class:`~risk_env.vector_env.RiskCrossingVectorEnv`
(arrays ``(B,)``, the :data:`~risk_env.ops.NUMPY` face).

Each function is written once against an :class:`~risk_env.ops.Ops` face, so one env and a batch
evaluate the very same formulas.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from risk_env import observation
from risk_env.dynamics import unicycle_step
from risk_env.ops import MATH, NUMPY, Ops
from risk_env.path import AnyPath, path_error, project
from risk_env.prediction import Belief, predict_step
from risk_env.risk import RiskEstimator
from risk_env.scenario import Scenario

Measurement = tuple[Any, Any, Any, Any, Any]
"""The object's ``(c1 [m], c2 [m], theta [rad], v [m/s], omega [rad/s])``, floats or arrays."""


def move_object(
    belief: Belief, measurement: Measurement, uniforms: Any | None, ops: Ops = NUMPY
) -> Measurement:
    """The object's next measurement given its one-step belief.

    ``uniforms=None``: the paper's motion, B's mean (its unicycle with constant inputs).
    ``uniforms`` on [0, 1), ``(..., 3)`` (numpy) or 3 floats: its next (c1, c2, v) is the draw
    :meth:`Belief.from_uniforms` makes, its heading advances with the mean model and its turn
    rate stays.
    """
    omega = measurement[4]
    if uniforms is None:
        return belief.x, belief.y, belief.theta, measurement[3], omega
    draw = belief.from_uniforms(uniforms, ops)
    return ops.part(draw, 0), ops.part(draw, 1), belief.theta, ops.part(draw, 2), omega


def advance_one(
    scenario: Scenario,
    estimator: RiskEstimator,
    pose: Any,
    action: tuple[float, float],
    measurement: Any,
    uniforms: list[float] | None,
    rng: np.random.Generator,
) -> tuple[tuple[float, float, float], Measurement, float]:
    """Steps 1-3 of the transition for one state, in Python floats (the MATH face).

    The ego at ``pose (c1, c2, theta)`` moves under ``action = (v, omega)``; the object moves
    from its one-step belief B made from ``measurement`` (``uniforms``: 3 floats on [0, 1) for
    the sampled motion, None for the paper's); R_{k+1|k} is the ego's new state against B (Monte
    Carlo draws from ``rng``). Returns the new pose, the new measurement and R.
    """
    v, omega = action
    x, y, theta = unicycle_step(pose[0], pose[1], pose[2], v, omega, scenario.dt, MATH)
    belief = predict_step(scenario, measurement, 1, MATH)
    moved = move_object(belief, measurement, uniforms, MATH)
    return (x, y, theta), moved, estimator.risk_one((x, y, theta, v), belief, rng=rng)


class Observed(NamedTuple):
    """What the env reports about a state; floats for one env, arrays ``(B, ...)`` for a batch."""

    obs: np.ndarray
    """Observation ``(..., 15)`` float32 (layout: :mod:`risk_env.observation`)."""
    path_error: np.ndarray
    """e ``(..., 4)`` float64 at the closest path point [m, m, rad, m/s]."""
    lam: Any
    """Arc length of the closest path point [m]."""
    distance: Any
    """Centre distance ego-object [m]."""
    collision: Any
    """``distance <= r_e + r_o``."""
    goal: Any
    """``lam >= lambda_g``."""
    error_norm: Any
    """``||e||`` [mixed units, as the paper's e_acc]."""


def observe(
    path: AnyPath,
    v_ref: float,
    collision_distance: float,
    ego_pose: tuple[Any, Any, Any],
    ego_input: tuple[Any, Any],
    measurement: Measurement,
    ops: Ops = NUMPY,
) -> Observed:
    """Observation and the state's path error, progress, distance, collision and goal flags."""
    x, y, theta = ego_pose
    v, omega = ego_input
    ox, oy, otheta, ov, oomega = measurement
    lam = project(path, x, y, ops)
    error = path_error(path, x, y, theta, v, lam, v_ref, ops)
    wrap = ops.wrap_angle
    values = ops.pack([x, y, wrap(theta), v, omega, ox, oy, wrap(otheta), ov, oomega, lam, *error])
    e1, e2, e3, e4 = error
    distance = ops.hypot(x - ox, y - oy)
    return Observed(
        obs=values.astype(np.float32),
        path_error=values[..., observation.PATH_ERROR],
        lam=lam,
        distance=distance,
        collision=distance <= collision_distance,
        goal=lam >= path.lambda_goal,
        error_norm=ops.sqrt(e1 * e1 + e2 * e2 + e3 * e3 + e4 * e4),
    )


def reward_terms(error_norm: Any, risk: Any, risk_weight: float) -> dict[str, Any]:
    """The named reward terms of a step: ``-||e_{k+1}||`` and ``-w R_{k+1|k}``."""
    return {"path_error": 0.0 - error_norm, "risk": 0.0 - risk_weight * risk}
