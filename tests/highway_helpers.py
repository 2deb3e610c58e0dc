"""Helpers of the tests on ``intersection-v2``'s road network (the ``network`` fixture: conftest)."""

from __future__ import annotations

from typing import Any

import numpy as np

LEFT_TURN = (("o0", "ir0", 0), ("ir0", "il1", 0), ("il1", "o1", 0))
"""``intersection-v2``'s ego route."""


def measurement(network: Any, lane_index: tuple, s: float, speed: float, turn: float = 0.0) -> np.ndarray:
    """A road user on the centreline of ``network``'s lane ``lane_index``, ``s`` [m] along it, at
    ``speed`` [m/s], heading the lane's way turned by ``turn`` [rad]: its measurement ``(5,)``."""
    lane = network.get_lane(lane_index)
    x, y = lane.position(s, 0.0)
    return np.array([x, y, lane.heading_at(s) + turn, speed, 0.0])
