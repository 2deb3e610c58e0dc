"""The routes a road user can take on highway-env's road network, for the lane predictor.

Everything here is read from the ``RoadNetwork`` through highway-env's own lane API
(``local_coordinates``, ``position``, ``heading_at``, ``width_at``, ``on_lane``, the graph of next
lanes and ``next_lane_given_next_road``). :func:`lane_coordinates`, :func:`lane_points` and
:func:`lane_headings` call a lane's methods on many points at once: for ``StraightLane`` and
``CircularLane`` (the lanes of highway-env's intersection, roundabout and highway) they evaluate
the same formulas as those methods with numpy over the points; any other lane type is called point
by point.

A :class:`Route` is a chain of lanes in driving order with one arc length s [m] along it, from the
start of its first lane; before the first lane and beyond the last one, those lanes' own
extrapolation continues (a straight line, a circle). :func:`routes_from` lists every route from a
lane through the graph: a lane continues into each next lane that starts where it ends
(:data:`JOIN_TOLERANCE`) in a heading within :data:`JOIN_ANGLE` of its own, so a graph edge that
turns back (an intersection's exit node that is also the start of the opposite approach lane) is no
continuation. :func:`rectangles_intersect` is highway-env's test of two cars' bodies, vectorised.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

LaneIndex = tuple[str, str, int]
"""highway-env's lane index ``(from node, to node, lane id)``."""

JOIN_TOLERANCE = 1.0
"""Largest gap [m] between a lane's end and a next lane's start for the two to join in a route."""
JOIN_ANGLE = math.pi / 3
"""Largest heading change [rad] from a lane's end to a next lane's start for the two to join."""


def wrap(angle: Any) -> Any:
    """Angles [rad] wrapped to [-pi, pi), as ``highway_env.utils.wrap_to_pi``."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def lane_kind(lane: Any) -> str:
    """``"straight"`` (a ``StraightLane``, not a ``SineLane``), ``"circular"`` or ``"other"``."""
    from highway_env.road.lane import CircularLane, StraightLane

    if type(lane) is StraightLane:
        return "straight"
    if type(lane) is CircularLane:
        return "circular"
    return "other"


def lane_coordinates(lane: Any, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``lane.local_coordinates`` of ``points (k, 2)`` [m]: longitudinal s ``(k,)`` and lateral r
    ``(k,)`` [m]."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    kind = lane_kind(lane)
    if kind == "straight":
        delta = p - lane.start
        return delta @ lane.direction, delta @ lane.direction_lateral
    if kind == "circular":
        delta = p - lane.center
        phi = np.arctan2(delta[:, 1], delta[:, 0])
        phi = lane.start_phase + wrap(phi - lane.start_phase)
        r = np.hypot(delta[:, 0], delta[:, 1])
        return lane.direction * (phi - lane.start_phase) * lane.radius, lane.direction * (lane.radius - r)
    coords = np.array([lane.local_coordinates(q) for q in p], dtype=float).reshape(-1, 2)
    return coords[:, 0], coords[:, 1]


def lane_points(lane: Any, s: np.ndarray, r: np.ndarray | float = 0.0) -> np.ndarray:
    """``lane.position(s, r)`` for arrays ``s (k,)`` (and ``r``, broadcast): points ``(k, 2)`` [m]."""
    s = np.asarray(s, dtype=float).reshape(-1)
    r = np.broadcast_to(np.asarray(r, dtype=float), s.shape)
    kind = lane_kind(lane)
    if kind == "straight":
        return lane.start + s[:, None] * lane.direction + r[:, None] * lane.direction_lateral
    if kind == "circular":
        phi = lane.direction * s / lane.radius + lane.start_phase
        rho = lane.radius - r * lane.direction
        return lane.center + rho[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    return np.array([lane.position(a, b) for a, b in zip(s, r, strict=True)], dtype=float).reshape(-1, 2)


def lane_headings(lane: Any, s: np.ndarray) -> np.ndarray:
    """``lane.heading_at(s)`` [rad] for an array ``s (k,)``."""
    s = np.asarray(s, dtype=float).reshape(-1)
    kind = lane_kind(lane)
    if kind == "straight":
        return np.full(s.shape, float(lane.heading))
    if kind == "circular":
        return lane.direction * s / lane.radius + lane.start_phase + np.pi / 2 * lane.direction
    return np.array([lane.heading_at(a) for a in s], dtype=float)


def lane_distance(lane: Any, point: np.ndarray) -> float:
    """How far [m] ``point`` lies off ``lane``: its lateral offset beyond half the lane's width plus
    how far its longitudinal coordinate lies before the start or beyond the end."""
    s, r = (float(c) for c in lane.local_coordinates(np.asarray(point, dtype=float)))
    width = float(lane.width_at(s))
    return max(abs(r) - width / 2, 0.0) + max(-s, 0.0) + max(s - float(lane.length), 0.0)


def check_lane(network: Any, index: Sequence[Any]) -> LaneIndex:
    """``index`` as a lane index of ``network``; ``ValueError`` naming it when the map has no such lane."""
    try:
        _from, _to, _id = index
        network.graph[_from][_to][_id]
    except (KeyError, IndexError, TypeError, ValueError):
        roads = sorted(f"{a}->{b}" for a, tos in network.graph.items() for b in tos)
        raise ValueError(
            f"lane {tuple(index) if isinstance(index, Sequence) else index!r} is not in the road"
            f" network; its roads are {', '.join(roads[:24])}{' ...' if len(roads) > 24 else ''}"
        ) from None
    return (_from, _to, int(_id))


GRID = 0.5
"""Spacing [m] at which a route samples its lanes' centreline (positions and headings from
highway-env's ``lane.position`` and ``lane.heading_at``); between samples it interpolates linearly
(off a circle of radius 9 m by less than 4 mm)."""
PAD = 100.0
"""How far [m] a route's samples reach before its start and beyond its end (its first and last
lanes extrapolated)."""


@dataclass(frozen=True, eq=False)
class Route:
    """A chain of lanes of ``network`` in driving order, with one arc length s [m] from the start
    of the first lane; sampled every :data:`GRID` metres from :data:`PAD` metres before its start
    to :data:`PAD` metres beyond its end."""

    network: Any = field(repr=False)
    """highway-env's ``RoadNetwork``."""
    lanes: tuple[LaneIndex, ...]
    """The lane indices, in driving order."""
    objects: tuple[Any, ...] = field(init=False, repr=False)
    """The lanes (highway-env ``AbstractLane``), same order as :attr:`lanes`."""
    lengths: np.ndarray = field(init=False, repr=False)
    """Lane lengths ``(L,)`` [m]."""
    offsets: np.ndarray = field(init=False, repr=False)
    """Route arc length at the start of each lane ``(L,)`` [m]."""
    samples: np.ndarray = field(init=False, repr=False)
    """``(K, 3)``: x [m], y [m] and heading [rad] (unwrapped along s) at s = -PAD, -PAD + GRID, ..."""

    def __post_init__(self) -> None:
        if not self.lanes:
            raise ValueError("a route needs at least one lane")
        objects = tuple(self.network.get_lane(index) for index in self.lanes)
        lengths = np.array([float(lane.length) for lane in objects])
        offsets = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
        object.__setattr__(self, "objects", objects)
        object.__setattr__(self, "lengths", lengths)
        object.__setattr__(self, "offsets", offsets)
        s = np.arange(-PAD, lengths.sum() + PAD + GRID, GRID)
        which = self.lane_of(s)
        samples = np.empty((len(s), 3))
        for k, lane in enumerate(objects):
            mask = which == k
            local = s[mask] - offsets[k]
            samples[mask, :2] = lane_points(lane, local)
            samples[mask, 2] = lane_headings(lane, local)
        samples[:, 2] = np.unwrap(samples[:, 2])
        object.__setattr__(self, "samples", samples)

    @property
    def length(self) -> float:
        """Total length [m]."""
        return float(self.lengths.sum())

    def lane_of(self, s: np.ndarray) -> np.ndarray:
        """Index (into :attr:`lanes`) of the lane that holds each arc length ``s`` (before the
        route: the first lane; beyond it: the last)."""
        where = np.searchsorted(self.offsets, np.asarray(s, dtype=float), side="right") - 1
        return np.minimum(np.maximum(where, 0), len(self.lanes) - 1)

    def interpolate(self, s: np.ndarray) -> np.ndarray:
        """``(..., 3)``: x [m], y [m] and heading [rad] of the centreline at ``s`` (clamped to the
        samples)."""
        return interpolate(self.samples[None], np.asarray(s, dtype=float)[None])[0]

    def position(self, s: np.ndarray, r: np.ndarray | float = 0.0) -> np.ndarray:
        """Points ``(..., 2)`` [m] at arc lengths ``s`` and lateral offsets ``r`` [m] (left of the
        direction of travel positive, highway-env's convention)."""
        xyh = self.interpolate(s)
        r = np.asarray(r, dtype=float)
        return xyh[..., :2] + r[..., None] * np.stack([-np.sin(xyh[..., 2]), np.cos(xyh[..., 2])], axis=-1)

    def heading(self, s: np.ndarray) -> np.ndarray:
        """Headings [rad] of the centreline at ``s``."""
        return self.interpolate(s)[..., 2]

    def curvature(self, s: np.ndarray, step: float = 0.5) -> np.ndarray:
        """Curvature [1/m] of the centreline at ``s`` (heading change per metre, over ``+- step``)."""
        s = np.asarray(s, dtype=float)
        return (self.heading(s + step) - self.heading(s - step)) / (2 * step)

    def speed_limit(self, s: np.ndarray) -> np.ndarray:
        """The lanes' speed limits [m/s] at ``s`` (``inf`` for a lane without one)."""
        limits = np.array(
            [math.inf if lane.speed_limit is None else float(lane.speed_limit) for lane in self.objects]
        )
        return limits[self.lane_of(s)]

    def locate(self, point: np.ndarray) -> tuple[float, float]:
        """``(s, r)`` [m] of ``point``: its coordinates on the lane of the route it lies along (the
        lane whose longitudinal range holds it with the smallest lateral offset; before the route
        the first lane, beyond it the last)."""
        point = np.asarray(point, dtype=float)
        best: tuple[float, float, float] | None = None
        last = len(self.lanes) - 1
        for k, lane in enumerate(self.objects):
            s, r = (float(c) for c in lane.local_coordinates(point))
            outside = max(-s, 0.0) * (k > 0) + max(s - float(lane.length), 0.0) * (k < last)
            score = abs(r) + outside
            if best is None or score < best[0]:
                best = (score, float(self.offsets[k]) + s, r)
        return best[1], best[2]

    def locate_many(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`locate` of every point of ``points (..., 2)`` [m] at once: ``(s, r)``, each of shape
        ``points.shape[:-1]`` (the same lane choice; coordinates by :func:`lane_coordinates`, which agree
        with highway-env's to rounding)."""
        p = np.asarray(points, dtype=float)
        flat = p.reshape(-1, 2)
        best = np.full(len(flat), np.inf)
        s_out, r_out = np.zeros(len(flat)), np.zeros(len(flat))
        last = len(self.lanes) - 1
        for k, lane in enumerate(self.objects):
            s, r = lane_coordinates(lane, flat)
            outside = np.maximum(-s, 0.0) * (k > 0) + np.maximum(s - float(lane.length), 0.0) * (k < last)
            score = np.abs(r) + outside
            better = score < best
            best = np.where(better, score, best)
            s_out = np.where(better, self.offsets[k] + s, s_out)
            r_out = np.where(better, r, r_out)
        return s_out.reshape(p.shape[:-1]), r_out.reshape(p.shape[:-1])

    def label(self) -> str:
        """The route as ``from>to>...`` of its nodes, e.g. ``"o0>ir0>il1>o1"``."""
        return ">".join([self.lanes[0][0], *(index[1] for index in self.lanes)])


def interpolate(samples: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Route samples ``(A, K, 3)`` (:attr:`Route.samples`, padded at the end by repetition) at arc
    lengths ``s (A, ...)`` [m], each row at its own route's: ``(A, ..., 3)``."""
    count = samples.shape[1]
    u = (np.asarray(s, dtype=float) + PAD) / GRID
    i = np.minimum(np.maximum(np.floor(u).astype(int), 0), count - 2)
    f = np.minimum(np.maximum(u - i, 0.0), 1.0)[..., None]
    rows = np.arange(samples.shape[0]).reshape((-1,) + (1,) * (np.ndim(s) - 1))
    return samples[rows, i] * (1 - f) + samples[rows, i + 1] * f


def next_lanes(network: Any, index: LaneIndex) -> list[LaneIndex]:
    """The lanes that continue ``index`` in the graph: one per next road (highway-env's
    ``next_lane_given_next_road`` picks its lane), if it joins (see the module docstring)."""
    _from, _to, _id = index
    lane = network.get_lane(index)
    end = np.asarray(lane.position(lane.length, 0.0), dtype=float)
    heading = float(lane.heading_at(lane.length))
    out = []
    for next_to in network.graph.get(_to, {}):
        next_id, _ = network.next_lane_given_next_road(_from, _to, _id, next_to, None, end)
        candidate = network.get_lane((_to, next_to, next_id))
        start = np.asarray(candidate.position(0.0, 0.0), dtype=float)
        turn = abs(float(wrap(candidate.heading_at(0.0) - heading)))
        if np.hypot(*(start - end)) <= JOIN_TOLERANCE and turn <= JOIN_ANGLE:
            out.append((_to, next_to, int(next_id)))
    return out


def routes_from(
    network: Any,
    index: LaneIndex,
    s0: float,
    reach: float,
    lookahead: float,
    following: Callable[[LaneIndex], list[LaneIndex]] | None = None,
) -> list[tuple[LaneIndex, ...]]:
    """Every route (its lanes) from lane ``index`` at arc length ``s0`` [m] on it: each is extended
    lane by lane while it ends less than ``reach`` [m] ahead, or until it has passed a fork (a
    lane with two or more continuations) as long as it ends less than ``lookahead`` [m] ahead; a
    lane without a continuation ends it. ``following``: :func:`next_lanes` on ``network`` unless
    given (a cache of it)."""
    index = check_lane(network, index)
    if following is None:
        following = functools.partial(next_lanes, network)
    done: list[tuple[LaneIndex, ...]] = []
    stack: list[tuple[tuple[LaneIndex, ...], float, bool]] = [
        ((index,), float(network.get_lane(index).length) - s0, False)
    ]
    while stack:
        lanes, ahead, branched = stack.pop()
        extend = ahead < reach or (not branched and ahead < lookahead)
        nexts = [f for f in following(lanes[-1]) if f not in lanes] if extend else []
        if not nexts:
            done.append(lanes)
            continue
        for nxt in reversed(nexts):
            length = float(network.get_lane(nxt).length)
            stack.append(((*lanes, nxt), ahead + length, branched or len(nexts) > 1))
    return done


_CORNERS = (
    np.array([[-1, -1], [-1, 1], [1, 1], [1, -1], [0, 0], [-1, 0], [1, 0], [0, -1], [0, 1]], dtype=float) / 2
)
"""The points highway-env's ``has_corner_inside`` tests, in (length, width) units: the corners,
the centre and the edges' middles."""


def rectangles_intersect(
    c1: np.ndarray, a1: np.ndarray, c2: np.ndarray, a2: np.ndarray, length: float, width: float
) -> np.ndarray:
    """highway-env's ``utils.rotated_rectangles_intersect`` for pairs of ``length x width``
    rectangles, vectorised: centres ``(P, 2)`` [m] and angles ``(P,)`` [rad] -> ``(P,)`` bool. As
    highway-env's, a pair intersects when a corner, edge middle or the centre of one lies in the
    other, each point turned by the other's angle (its convention, kept as it is)."""

    def inside(ca: np.ndarray, aa: np.ndarray, cb: np.ndarray, ab: np.ndarray) -> np.ndarray:
        local = _CORNERS * np.array([length, width])  # (9, 2)
        ca_, sa_ = np.cos(aa)[:, None], np.sin(aa)[:, None]
        points = ca[:, None, :] + np.stack(
            [
                ca_ * local[None, :, 0] - sa_ * local[None, :, 1],
                sa_ * local[None, :, 0] + ca_ * local[None, :, 1],
            ],
            -1,
        )  # (P, 9, 2)
        d = points - cb[:, None, :]
        cb_, sb_ = np.cos(ab)[:, None], np.sin(ab)[:, None]
        u = cb_ * d[..., 0] - sb_ * d[..., 1]
        w = sb_ * d[..., 0] + cb_ * d[..., 1]
        return ((np.abs(u) <= length / 2) & (np.abs(w) <= width / 2)).any(axis=1)

    return inside(c1, a1, c2, a2) | inside(c2, a2, c1, a1)
