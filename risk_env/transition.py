"""The env's transition as pure functions, shared by :class:`~risk_env.env.RiskCrossingEnv` (floats)
and :class:`~risk_env.vector_env.RiskCrossingVectorEnv` (arrays ``(B,)``).

Each function broadcasts: pass Python floats for one env, numpy arrays for a batch.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from risk_env.ops import NUMPY
from risk_env.path import AnyPath, path_error, project
from risk_env.prediction import Belief

Measurement = tuple[Any, Any, Any, Any, Any]
"""The object's ``(c1 [m], c2 [m], theta [rad], v [m/s], omega [rad/s])``, floats or arrays."""


def move_object(belief: Belief, measurement: Measurement, uniforms: np.ndarray | None) -> Measurement:
    """The object's next measurement given its one-step belief.

    ``uniforms=None``: the paper's motion, B's mean (its unicycle with constant inputs).
    ``uniforms (..., 3)`` on [0, 1): its next (c1, c2, v) is the draw :meth:`Belief.from_uniforms`
    makes, its heading advances with the mean model and its turn rate stays.
    """
    omega = measurement[4]
    if uniforms is None:
        return belief.x, belief.y, belief.theta, measurement[3], omega
    draw = belief.from_uniforms(uniforms)
    return draw[..., 0], draw[..., 1], belief.theta, draw[..., 2], omega


class Observed(NamedTuple):
    """What the env reports about a state; floats for one env, arrays ``(B, ...)`` for a batch."""

    obs: np.ndarray
    """Observation ``(..., 15)`` float32 (layout: :mod:`risk_env.observation`)."""
    path_error: np.ndarray
    """e ``(..., 4)`` at the closest path point [m, m, rad, m/s]."""
    lam: Any
    """Arc length of the closest path point [m]."""
    distance: Any
    """Centre distance ego-object [m]."""
    collision: Any
    """``distance <= r_e + r_o``."""
    goal: Any
    """``lam >= lambda_g``."""


def observe(
    path: AnyPath,
    v_ref: float,
    collision_distance: float,
    ego_pose: tuple[Any, Any, Any],
    ego_input: tuple[Any, Any],
    measurement: Measurement,
) -> Observed:
    """Observation and the state's path error, progress, distance, collision and goal flags."""
    x, y, theta = ego_pose
    v, omega = ego_input
    ox, oy, otheta, ov, oomega = measurement
    lam = project(path, x, y)
    error = path_error(path, x, y, theta, v, lam, v_ref)
    wrap = NUMPY.wrap_angle
    parts = (x, y, wrap(theta), v, omega, ox, oy, wrap(otheta), ov, oomega, lam, *error)
    obs = np.stack(np.broadcast_arrays(*parts), axis=-1).astype(np.float32)
    distance = np.hypot(x - ox, y - oy)
    return Observed(
        obs=obs,
        path_error=np.stack(np.broadcast_arrays(*error), axis=-1).astype(float),
        lam=lam,
        distance=distance,
        collision=distance <= collision_distance,
        goal=lam >= path.lambda_goal,
    )


def reward_terms(error: np.ndarray, risk: Any, risk_weight: float) -> dict[str, Any]:
    """The named reward terms of a step: ``-||e_{k+1}||`` and ``-w R_{k+1|k}``."""
    return {"path_error": 0.0 - np.sqrt(np.sum(error * error, axis=-1)), "risk": 0.0 - risk_weight * risk}
