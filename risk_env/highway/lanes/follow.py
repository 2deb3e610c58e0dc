r"""Road users ahead on the ego's own route: boxes the ego follows, never passes beside.

A lane predictor's box of a road user holds where it may be; a robust planner keeps the ego's discs
off it. For a road user driving ahead of the ego along the ego's own route that leaves the plan a
way past that no driver takes: beside the box, at the edge of the ego's corridor, where a plan that
slows behind a car in its lane stops askew and, turning as a car does, cannot straighten out again.
:func:`follow_leaders` widens such boxes across the route to the ego's corridor, at every stage
where the mode's mean lies on the route ahead of the ego, in its lane and heading its way: the only
plan that keeps off them stays behind, so the worst-case rows become a following distance, the gap
to the slowest the leader can brake (the box's rear end). The standard deviations are left as they
are (the expected risks see the road user where it is likely).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from risk_env import checks
from risk_env.highway.lanes.routes import Route, wrap
from risk_env.prediction.mixture import Mixture

LEADER_CONE = math.pi / 4
"""Largest angle [rad] between a mean's heading and the route's for a leader."""
LANE_HALF_WIDTH = 2.0
"""Largest lateral offset [m] of a mean from the route's centreline for a leader (half of
highway-env's 4 m lane)."""


@dataclass(frozen=True)
class Leaders:
    """What :func:`follow_leaders` needs of the ego this step: its ``route``, its position
    ``(x, y)`` [m] and the half width [m] of its corridor about the route's centreline."""

    route: Route
    position: tuple[float, float]
    corridor: float

    def __post_init__(self) -> None:
        if not isinstance(self.route, Route):
            raise TypeError(f"Leaders.route must be a Route, got {checks.describe(self.route)}")
        checks.finite_reals("Leaders.position", self.position, 2)
        checks.positive("Leaders.corridor", self.corridor)


def follow_leaders(mixtures: list[Mixture], leaders: Leaders) -> list[Mixture]:
    r"""``mixtures`` with each mode's truncation box widened across, $h_y \ge |r| + c$ ($r$: the
    mean's offset from the route, $c$: the corridor), at every stage $n \ge 1$ where its mean lies
    ahead of the ego on its route (within :data:`LANE_HALF_WIDTH` of the centreline, heading within
    :data:`LEADER_CONE` of it); every other stage and mode as it was."""
    ego_s = float(leaders.route.locate_many(np.asarray(leaders.position, dtype=float))[0])
    out = []
    for mixture in mixtures:
        modes = []
        for mode in mixture.modes:
            b = mode.beliefs
            x, y = np.asarray(b.x, dtype=float), np.asarray(b.y, dtype=float)
            s, r = leaders.route.locate_many(np.stack([x, y], axis=-1))
            heading = leaders.route.heading(s)
            ahead = (s > ego_s) & (np.abs(r) <= LANE_HALF_WIDTH)
            ahead &= np.abs(wrap(np.asarray(b.theta, dtype=float) - heading)) <= LEADER_CONE
            ahead[0] = False  # n = 0: the measurement, which no row reads
            if ahead.any():
                half_y = np.asarray(b.half_y, dtype=float)
                wide = np.where(ahead, np.maximum(half_y, np.abs(r) + leaders.corridor), half_y)
                mode = dataclasses.replace(mode, beliefs=dataclasses.replace(b, half_y=wide))
            modes.append(mode)
        out.append(Mixture(tuple(modes)))
    return out
