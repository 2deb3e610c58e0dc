"""Every lane of a highway-env road network as arrays, for the lane predictor.

:class:`LaneTable` holds what the speed model asks of every lane at every step, computed for all
lanes and points at once: the lanes' local coordinates (highway-env's ``local_coordinates`` of
``StraightLane`` and ``CircularLane``, the same formulas over arrays; other lane types are called
point by point), the closest lane as highway-env's ``RoadNetwork.get_closest_lane_index`` picks it,
and the lanes highway-env's ``Road.neighbour_vehicles`` searches for a vehicle's leader
(:func:`search_lanes`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from risk_env.highway.lanes.routes import LaneIndex, lane_coordinates, lane_kind, wrap

ON_LANE_MARGIN = 1.0
"""highway-env's ``on_lane(..., margin=1)`` of the neighbour search [m]."""


def search_lanes(network: Any, index: LaneIndex, connected: bool) -> list[tuple[LaneIndex, float]]:
    """The lanes ``Road.neighbour_vehicles`` searches for the neighbours of a vehicle on ``index``,
    with the offsets [m] that put their arc lengths on its lane's, in highway-env's order."""
    lane = network.get_lane(index)
    out: list[tuple[LaneIndex, float]] = [(index, 0.0)]
    if not connected:
        return out
    _from, _to, _id = index
    for next_to, following in network.graph.get(_to, {}).items():
        if following:
            out.append(((_to, next_to, _id if _id < len(following) else 0), float(lane.length)))
    for start, to_dict in network.graph.items():
        previous = to_dict.get(_from)
        if previous:
            chosen = _id if _id < len(previous) else 0
            out.append(((start, _from, chosen), -float(previous[chosen].length)))
    return out


class LaneTable:
    """Every lane of a network as arrays: what the neighbour search and the yielding rule read."""

    def __init__(self, network: Any, connected: bool) -> None:
        lanes = network.lanes_dict()
        self.indices: list[LaneIndex] = list(lanes)
        self.objects = [lanes[index] for index in self.indices]
        self.id = {index: i for i, index in enumerate(self.indices)}
        searches = [search_lanes(network, index, connected) for index in self.indices]
        width = max(len(s) for s in searches)
        self.search = np.full((len(searches), width), -1, dtype=int)
        """``(L, J)``: the lanes searched from each lane, in order (-1: none)."""
        self.search_offset = np.zeros((len(searches), width))
        for i, found in enumerate(searches):
            for j, (index, offset) in enumerate(found):
                self.search[i, j] = self.id[index]
                self.search_offset[i, j] = offset
        self.half_width = np.array([lane.width_at(0.0) / 2 + ON_LANE_MARGIN for lane in self.objects])
        self.length = np.array([float(lane.length) for lane in self.objects])
        self.margin = np.array([float(lane.VEHICLE_LENGTH) for lane in self.objects])
        self.priority = np.array([float(getattr(lane, "priority", 0)) for lane in self.objects])
        self.limit = np.array(
            [math.inf if lane.speed_limit is None else float(lane.speed_limit) for lane in self.objects]
        )

        kinds = [lane_kind(lane) for lane in self.objects]
        self._straight = np.array([i for i, k in enumerate(kinds) if k == "straight"], dtype=int)
        self._circular = np.array([i for i, k in enumerate(kinds) if k == "circular"], dtype=int)
        self._other = [i for i, k in enumerate(kinds) if k == "other"]
        lanes = [self.objects[i] for i in self._straight]
        self._start = np.array([lane.start for lane in lanes]).reshape(-1, 2)
        self._along = np.array([lane.direction for lane in lanes]).reshape(-1, 2)
        self._across = np.array([lane.direction_lateral for lane in lanes]).reshape(-1, 2)
        lanes = [self.objects[i] for i in self._circular]
        self._center = np.array([lane.center for lane in lanes]).reshape(-1, 2)
        self._radius = np.array([lane.radius for lane in lanes])
        self._phase = np.array([lane.start_phase for lane in lanes])
        self._turn = np.array([lane.direction for lane in lanes], dtype=float)

    def locate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Local coordinates (longitudinal, lateral) ``(L, B)`` [m] of ``points (B, 2)`` on every
        lane: :func:`~risk_env.highway.lanes.routes.lane_coordinates` for all lanes at once."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        s = np.empty((len(self.objects), len(points)))
        r = np.empty(s.shape)
        delta = points[None, :, :] - self._start[:, None, :]
        s[self._straight] = np.einsum("lbd,ld->lb", delta, self._along)
        r[self._straight] = np.einsum("lbd,ld->lb", delta, self._across)
        delta = points[None, :, :] - self._center[:, None, :]
        phi = np.arctan2(delta[..., 1], delta[..., 0])
        phase = self._phase[:, None]
        phi = phase + wrap(phi - phase)
        s[self._circular] = self._turn[:, None] * (phi - phase) * self._radius[:, None]
        distance = np.hypot(delta[..., 0], delta[..., 1])
        r[self._circular] = self._turn[:, None] * (self._radius[:, None] - distance)
        for i in self._other:
            s[i], r[i] = lane_coordinates(self.objects[i], points)
        return s, r

    def headings(self, s: np.ndarray) -> np.ndarray:
        """Every lane's heading [rad] at its longitudinal coordinates ``s (L, B)`` [m]
        (``lane.heading_at``)."""
        out = np.empty(s.shape)
        out[self._straight] = np.array([self.objects[i].heading for i in self._straight])[:, None]
        turn, phase = self._turn[:, None], self._phase[:, None]
        out[self._circular] = turn * s[self._circular] / self._radius[:, None] + phase + np.pi / 2 * turn
        for i in self._other:
            out[i] = [self.objects[i].heading_at(x) for x in s[i]]
        return out

    def closest(self, s: np.ndarray, r: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """The index (into :attr:`indices`) of the closest lane to each of B points, as highway-env's
        ``RoadNetwork.get_closest_lane_index(position, heading)``: from their coordinates on every
        lane ``s, r (L, B)`` [m] (:meth:`locate`) and ``heading (B,)`` [rad]."""
        length = self.length[:, None]
        angle = np.abs(wrap(heading[None, :] - self.headings(s)))
        return np.argmin(np.abs(r) + np.maximum(s - length, 0) + np.maximum(-s, 0) + angle, axis=0)

    def coordinates(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Longitudinal coordinates ``(L, B)`` [m] of ``points (B, 2)`` on every lane, and whether
        each lies on it (highway-env's ``on_lane`` with the neighbour search's margin)."""
        s, r = self.locate(points)
        margin, length = self.margin[:, None], self.length[:, None]
        return s, (np.abs(r) <= self.half_width[:, None]) & (s >= -margin) & (s < length + margin)
