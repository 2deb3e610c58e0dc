r"""The reference path: point, heading, closest-point projection, timing law and path error.

The arc of :class:`~risk_env.scenario.scenario.ReferencePath` is written in the goal's frame as
$l_x = l \,\mathrm{sinc}(\kappa l)$, $l_y = l\, (\kappa l / 2)\, \mathrm{sinc}(\kappa l / 2)^2$, smooth
for any
$\kappa$ including 0, and defined for every arc length: beyond $\lambda_g$ it continues the arc, so an MPC
horizon never runs off the path.

Every function takes a :class:`~risk_env.scenario.scenario.ReferencePath` (floats) or a :class:`PathBatch`
(one path per batch entry, numpy arrays), so a batch of environments with different paths is
stepped with the same formulas.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from risk_env.models.ops import NUMPY, Ops
from risk_env.scenario.scenario import Pose, ReferencePath


@dataclass
class _GoalBatch:
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    cos: np.ndarray
    r"""$\cos \theta$, kept with it (the goal is a parameter, not a variable)."""
    sin: np.ndarray
    r"""$\sin \theta$."""

    @classmethod
    def of(cls, x: Any, y: Any, theta: Any) -> _GoalBatch:
        """Goal poses from ``(B,)`` arrays (or floats)."""
        return cls(x, y, theta, np.cos(theta), np.sin(theta))


@dataclass
class PathBatch:
    """Arcs of a batch, one per entry: the fields of :class:`ReferencePath` as arrays ``(B,)``.

    Mutable so that a vectorised env can re-pose one entry in place on reset.
    """

    curvature: np.ndarray
    r"""$\kappa$ ``(B,)`` [1/m]."""
    goal: _GoalBatch | Pose
    """Goal poses: ``x``, ``y`` [m], ``theta`` [rad], each ``(B,)``; or one goal for every entry."""
    lambda_goal: float = 0.0

    @classmethod
    def of(cls, path: ReferencePath, size: int) -> PathBatch:
        """``size`` copies of ``path``."""
        g = path.goal
        return cls(
            np.full(size, path.curvature),
            _GoalBatch.of(np.full(size, g.x), np.full(size, g.y), np.full(size, g.theta)),
        )

    def set(self, index: int | np.ndarray, path: ReferencePath) -> None:
        """Make entry ``index`` (an int, index array or bool mask) equal to ``path``."""
        self.curvature[index] = path.curvature
        g = path.goal
        self.goal.x[index], self.goal.y[index], self.goal.theta[index] = g.as_tuple()
        self.goal.cos[index], self.goal.sin[index] = math.cos(g.theta), math.sin(g.theta)


def _goal_frame(path: AnyPath) -> tuple[Any, Any, Any, Any, Any]:
    """The goal's ``(x, y, theta, cos theta, sin theta)``: floats of a path, arrays of a batch."""
    g = path.goal
    if isinstance(g, Pose):
        return g.x, g.y, g.theta, math.cos(g.theta), math.sin(g.theta)
    return g.x, g.y, g.theta, g.cos, g.sin


AnyPath = ReferencePath | PathBatch
"""A single path (floats) or a batch (arrays)."""


def point(path: AnyPath, lam: Any, ops: Ops = NUMPY) -> tuple[Any, Any, Any]:
    r"""$y_P(\lambda)$: ``(c1 [m], c2 [m], theta_P [rad])`` at arc length $\lambda$ = ``lam`` [m]."""
    k = path.curvature
    a = k * lam
    lx = lam * ops.sinc(a)
    s = ops.sinc(0.5 * a)
    ly = lam * 0.5 * a * s * s
    gx, gy, gth, cg, sg = _goal_frame(path)
    return gx + cg * lx - sg * ly, gy + sg * lx + cg * ly, gth + a


def project(path: AnyPath, x: Any, y: Any, ops: Ops = NUMPY) -> Any:
    """Arc length [m] of the closest point of the (continued) path to ``(x, y)`` [m]."""
    gx, gy, _, cg, sg = _goal_frame(path)
    px = cg * (x - gx) + sg * (y - gy)
    py = -sg * (x - gx) + cg * (y - gy)
    k = path.curvature
    # the angle subtended at the arc's centre, atan2(k px, 1 - k py), over k; px on a line
    if isinstance(k, np.ndarray):
        straight = k == 0.0
        if not straight.any():
            return ops.atan2(k * px, 1.0 - k * py) / k
        lam = ops.atan2(k * px, 1.0 - k * py) / np.where(straight, 1.0, k)
        return np.where(straight, px, lam)
    if k == 0.0:
        return px
    return ops.atan2(k * px, 1.0 - k * py) / k


def lateral_offset(path: ReferencePath, x: Any, y: Any, ops: Ops = NUMPY) -> Any:
    r"""Signed distance [m] of ``(x, y)`` [m] from the (continued) arc, positive to its left:
    $(1 - \sqrt{(\kappa p_x)^2 + (1 - \kappa p_y)^2}) / \kappa$ in the goal's frame (the arc's centre
    at $(0, 1/\kappa)$), $p_y$ on a straight path."""
    gx, gy, _, cg, sg = _goal_frame(path)
    px = cg * (x - gx) + sg * (y - gy)
    py = -sg * (x - gx) + cg * (y - gy)
    k = path.curvature
    if k == 0.0:
        return py
    return (1.0 - ops.sqrt((k * px) ** 2 + (1.0 - k * py) ** 2)) / k


def timing_law(path: AnyPath, lam: Any, theta: Any, u2: Any, dt: float, ops: Ops = NUMPY) -> Any:
    r"""$\lambda^+ = \lambda + u_2 \cos(\theta - \theta_P(\lambda))\, T$ (paper Sec. VI-B)."""
    theta_p = path.goal.theta + path.curvature * lam
    return lam + u2 * ops.cos(theta - theta_p) * dt


def path_error(
    path: AnyPath,
    x: Any,
    y: Any,
    theta: Any,
    speed: Any,
    lam: Any,
    v_ref: float,
    ops: Ops = NUMPY,
    wrap: bool = True,
) -> tuple[Any, Any, Any, Any]:
    r"""$e = (c_1 - c_{1,P},\, c_2 - c_{2,P},\, \theta - \theta_P,\, v - v_{ref})$ at arc length ``lam``.

    ``wrap`` maps the heading error to $[-\pi, \pi)$; the MPC, whose headings are unwrapped near the
    path's, uses the smooth unwrapped difference.
    """
    px, py, pth = point(path, lam, ops)
    dth = theta - pth
    if wrap:
        dth = ops.wrap_angle(dth)
    return x - px, y - py, dth, speed - v_ref


def path_error_vector(
    path: ReferencePath, pose: np.ndarray, speed: float, v_ref: float
) -> tuple[np.ndarray, float]:
    """$e_k$ at the closest path point of ``pose (3,)``: returns ``(e (4,), lambda)``."""
    lam = float(project(path, pose[0], pose[1]))
    e = path_error(path, pose[0], pose[1], pose[2], speed, lam, v_ref)
    return np.array(e, dtype=float), lam
