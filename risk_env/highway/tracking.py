"""The other vehicles' measurements for the adapter: highway-env's observed rows with a turn rate
from the heading change of the vehicle associated with each one step earlier."""

from __future__ import annotations

import numpy as np

from risk_env.models.dynamics import unicycle_step
from risk_env.models.ops import NUMPY

TRACK_GATE = 2.0
"""Largest distance [m] between a vehicle and where one seen a step earlier was predicted to be,
for the two to count as the same vehicle (turn-rate estimate)."""


def measure(rows: np.ndarray, previous: np.ndarray, dt: float) -> np.ndarray:
    """Measurements ``(K, 5)`` of the vehicles ``rows (K, 4)`` (x, y, heading, speed): the turn rate
    from the heading change since the ``previous`` step's measurement ``(K', 5)`` (``dt`` [s] ago)
    of an associated vehicle (within :data:`TRACK_GATE` of where it was predicted), else 0."""
    omega = np.zeros(len(rows))
    prev = previous
    if len(rows) and len(prev):
        px, py, _ = unicycle_step(prev[:, 0], prev[:, 1], prev[:, 2], prev[:, 3], prev[:, 4], dt, NUMPY)
        gap = np.hypot(rows[:, 0, None] - px[None, :], rows[:, 1, None] - py[None, :])
        nearest = np.argmin(gap, axis=1)
        matched = gap[np.arange(len(rows)), nearest] < TRACK_GATE
        turn = NUMPY.wrap_angle(rows[:, 2] - prev[nearest, 2]) / dt
        omega = np.where(matched, turn, 0.0)
    return np.column_stack([rows, omega]) if len(rows) else np.zeros((0, 5))
