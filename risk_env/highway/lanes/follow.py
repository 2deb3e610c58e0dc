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
from typing import NamedTuple

import numpy as np

from risk_env import checks
from risk_env.highway.lanes.routes import Route, wrap
from risk_env.prediction.mixture import Mixture

LEADER_CONE = math.pi / 4
"""Largest angle [rad] between a mean's heading and the route's for a leader."""
LANE_HALF_WIDTH = 2.0
"""Largest lateral offset [m] of a mean from the route's centreline for a leader (half of
highway-env's 4 m lane)."""


LEADER_MARGIN = 2.0
"""Room [m] a capped ego keeps between its body and a stopped leader's, which may still roll back
(:func:`leader_gap`)."""


LEADER_BRAKING = 6.0
"""A leader's full braking [m/s²] (highway-env's ``IDMVehicle.ACC_MAX``, to which its IDM is
clipped)."""


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


class OnRoute(NamedTuple):
    """Where points lie on the ego's route (:func:`ahead_on_route`), each field ``(...)``."""

    ahead: np.ndarray
    """Whether each is a leader's place: ahead of the ego, within :data:`LANE_HALF_WIDTH` of the
    centreline and heading within :data:`LEADER_CONE` of it (bool)."""
    along: np.ndarray
    """Its arc length less the ego's [m]."""
    offset: np.ndarray
    """Its offset from the centreline [m]."""
    turn: np.ndarray
    """Its heading less the route's there [rad], wrapped."""


def ahead_on_route(route: Route, ego_s: float, points: np.ndarray, headings: np.ndarray) -> OnRoute:
    """Where ``points (..., 2)`` [m] heading ``headings (...)`` [rad] lie on the ego's ``route``, the
    ego at arc length ``ego_s`` [m] (:class:`OnRoute`)."""
    s, r = route.locate_many(np.asarray(points, dtype=float))
    turn = wrap(np.asarray(headings, dtype=float) - route.heading(s))
    ahead = (s > ego_s) & (np.abs(r) <= LANE_HALF_WIDTH) & (np.abs(turn) <= LEADER_CONE)
    return OnRoute(ahead, s - ego_s, r, turn)


def ego_arc(route: Route, position: tuple[float, float]) -> float:
    """The arc length [m] of the ego at ``position`` on its ``route``."""
    return float(route.locate_many(np.asarray(position, dtype=float))[0])


def leader_gap(
    route: Route, position: tuple[float, float], rows: np.ndarray, length: float
) -> tuple[float, float] | None:
    """``(gap [m], speed [m/s])`` of the nearest road user measured as ``rows (m, 5)`` ahead of the
    ego at ``position`` on its ``route`` (:func:`ahead_on_route`): the room between their bodies of
    ``length`` [m] along the route less :data:`LEADER_MARGIN`, and its speed along the route (at
    least 0); None when none is ahead."""
    rows = np.asarray(rows, dtype=float).reshape(-1, 5)
    if not len(rows):
        return None
    place = ahead_on_route(route, ego_arc(route, position), rows[:, :2], rows[:, 2])
    if not place.ahead.any():
        return None
    k = np.flatnonzero(place.ahead)[int(np.argmin(place.along[place.ahead]))]
    along = rows[k, 3] * math.cos(float(place.turn[k]))
    return float(place.along[k]) - length - LEADER_MARGIN, max(along, 0.0)


def leader_speed(gap: tuple[float, float] | None, braking: float) -> float:
    r"""$\sqrt{2 b (g + v_l^2 / (2 a_l))}$ [m/s]: the highest speed from which braking at ``braking``
    $b$ [m/s²] stops the ego within ``gap`` $= (g, v_l)$ (:func:`leader_gap`; $g$ at least 0) plus
    the distance its leader needs to stop from $v_l$ at highway-env's full braking $a_l$
    (:data:`LEADER_BRAKING`); inf without a leader."""
    if gap is None:
        return math.inf
    room, v_l = gap
    return math.sqrt(2.0 * braking * (max(room, 0.0) + v_l**2 / (2.0 * LEADER_BRAKING)))


def follow_leaders(mixtures: list[Mixture], leaders: Leaders) -> list[Mixture]:
    r"""``mixtures`` with each mode's truncation box widened across, $h_y \ge |r| + c$ ($r$: the
    mean's offset from the route, $c$: the corridor), at every stage $n \ge 1$ where its mean lies
    ahead of the ego on its route (within :data:`LANE_HALF_WIDTH` of the centreline, heading within
    :data:`LEADER_CONE` of it); every other stage and mode as it was."""
    ego_s = ego_arc(leaders.route, leaders.position)
    out = []
    for mixture in mixtures:
        modes = []
        for mode in mixture.modes:
            b = mode.beliefs
            x, y = np.asarray(b.x, dtype=float), np.asarray(b.y, dtype=float)
            place = ahead_on_route(
                leaders.route, ego_s, np.stack([x, y], axis=-1), np.asarray(b.theta, dtype=float)
            )
            ahead, r = place.ahead, place.offset
            ahead[0] = False  # n = 0: the measurement, which no row reads
            if ahead.any():
                half_y = np.asarray(b.half_y, dtype=float)
                wide = np.where(ahead, np.maximum(half_y, np.abs(r) + leaders.corridor), half_y)
                mode = dataclasses.replace(mode, beliefs=dataclasses.replace(b, half_y=wide))
            modes.append(mode)
        out.append(Mixture(tuple(modes)))
    return out
