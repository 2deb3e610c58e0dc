"""A belief's own frame: its covariance and truncation box are aligned with the axes turned by
``frame`` [rad] from c1 (:attr:`risk_env.prediction.belief.Belief.frame`). Offsets go between the world
and that frame with these two rotations, written once for every face of :mod:`risk_env.models.ops`."""

from __future__ import annotations

from typing import Any

import numpy as np

from risk_env.models.ops import NUMPY, Ops


def _zero(frame: Any) -> bool:
    """Whether ``frame`` is 0: the number, or a numpy array of zeros (not a symbol)."""
    if isinstance(frame, (int, float, np.floating)):
        return frame == 0.0
    return isinstance(frame, np.ndarray) and not frame.any()


def to_frame(dx: Any, dy: Any, frame: Any, ops: Ops = NUMPY) -> tuple[Any, Any]:
    """A world offset ``(dx, dy)`` [m] in the frame turned by ``frame`` [rad] from c1: its
    components ``(along, across)`` the frame's first axis. A frame of exactly 0 (a number or an
    array of zeros) returns the offset itself, bit for bit (the paper's world-aligned beliefs)."""
    if _zero(frame):
        return dx, dy
    c, s = ops.cos(frame), ops.sin(frame)
    return c * dx + s * dy, c * dy - s * dx


def from_frame(along: Any, across: Any, frame: Any, ops: Ops = NUMPY) -> tuple[Any, Any]:
    """The inverse of :func:`to_frame`: components in the frame -> the world offset ``(dx, dy)``."""
    if _zero(frame):
        return along, across
    c, s = ops.cos(frame), ops.sin(frame)
    return c * along - s * across, s * along + c * across
