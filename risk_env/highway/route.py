"""The route of highway-env's controlled vehicle as our reference paths: each lane of the route
(straight or circular) as a :class:`~risk_env.scenario.scenario.ReferencePath`, and the route's arc length."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from risk_env.models.path import point, project
from risk_env.scenario.scenario import Pose, ReferencePath

LaneIndex = tuple[str, str, int]
"""highway-env's lane index ``(from node, to node, lane id)``."""


def lane_path(lane: Any) -> ReferencePath:
    r"""The highway-env lane as our arc: goal = the lane's end (position and heading), curvature 0
    (``StraightLane``) or ``direction / radius`` (``CircularLane``), $\lambda_{start} = -\mathrm{length}$."""
    from highway_env.road.lane import CircularLane, SineLane, StraightLane

    if isinstance(lane, CircularLane):
        curvature = lane.direction / lane.radius
    elif isinstance(lane, StraightLane) and not isinstance(lane, SineLane):
        curvature = 0.0
    else:
        raise ValueError(
            f"the adapter follows straight and circular lanes only (our path is one arc per lane);"
            f" got a {type(lane).__name__}"
        )
    end = lane.position(lane.length, 0.0)
    return ReferencePath(
        goal=Pose(float(end[0]), float(end[1]), float(lane.heading_at(lane.length))),
        curvature=float(curvature),
        lambda_start=-float(lane.length),
    )


@dataclass(frozen=True)
class RoutePath:
    """A route of highway-env lanes as a chain of our reference arcs, one per lane.

    Route arc length s [m] runs from the start of the first lane; beyond the last lane the last
    arc continues.
    """

    lanes: tuple[LaneIndex, ...]
    """highway-env lane indices ``(from, to, id)``, in driving order."""
    paths: tuple[ReferencePath, ...]
    r"""The lanes as arcs (same order), each ending at its lane's end with $\lambda_g = 0$."""

    def __post_init__(self) -> None:
        if not self.paths or len(self.paths) != len(self.lanes):
            raise ValueError(
                f"a route needs one path per lane, got {len(self.lanes)} lanes, {len(self.paths)} paths"
            )

    @classmethod
    def from_lanes(cls, network: Any, lanes: Sequence[LaneIndex]) -> RoutePath:
        """The route through ``lanes`` of a highway-env ``RoadNetwork``."""
        lanes = tuple(tuple(index) for index in lanes)
        return cls(lanes=lanes, paths=tuple(lane_path(network.get_lane(index)) for index in lanes))

    @classmethod
    def of_vehicle(cls, network: Any, vehicle: Any, destination: str) -> RoutePath:
        """From ``vehicle``'s lane to the node ``destination`` (shortest path in the network)."""
        current = tuple(vehicle.lane_index)
        nodes = network.shortest_path(current[1], destination)
        if current[1] != destination and not nodes:
            raise ValueError(f"no route from lane {current} to {destination!r}")
        lanes = [current]
        for start, end in zip(nodes[:-1], nodes[1:], strict=True):
            lanes.append((start, end, min(current[2], len(network.graph[start][end]) - 1)))
        return cls.from_lanes(network, lanes)

    @property
    def lengths(self) -> np.ndarray:
        """Lane lengths ``(L,)`` [m]."""
        return np.array([-p.lambda_start for p in self.paths])

    @property
    def offsets(self) -> np.ndarray:
        """Route arc length at the start of each lane ``(L,)`` [m]."""
        return np.concatenate([[0.0], np.cumsum(self.lengths)[:-1]])

    def position(self, s: np.ndarray | float) -> np.ndarray:
        """Points ``(..., 2)`` [m] at route arc lengths ``s`` [m]."""
        s = np.asarray(s, dtype=float)
        lane = np.clip(np.searchsorted(self.offsets, s, side="right") - 1, 0, len(self.paths) - 1)
        out = np.empty(s.shape + (2,))
        for i, path in enumerate(self.paths):
            mask = lane == i
            if np.any(mask):
                lam = s[mask] - self.offsets[i] + path.lambda_start
                px, py, _ = point(path, lam)
                out[mask] = np.stack([px, py], axis=-1)
        return out

    def progress(self, lane: int, x: float, y: float) -> float:
        """Route arc length [m] of the closest point to ``(x, y)`` on lane ``lane``'s arc."""
        path = self.paths[lane]
        return float(self.offsets[lane] + project(path, x, y) - path.lambda_start)

    def polyline(self, spacing: float = 1.0) -> np.ndarray:
        """The whole route sampled every ``spacing`` metres ``(M, 2)`` [m]."""
        total = float(np.sum(self.lengths))
        return self.position(np.linspace(0.0, total, max(int(total / spacing), 1) + 1))


JUNCTION_PREFIX = "ir"
"""A route lane from a node named so lies inside highway-env's intersection (``ir*`` -> ``il*``)."""


def junction_span(route: RoutePath) -> tuple[float, float] | None:
    """Route arc lengths ``(s_in, s_out)`` [m] of the route's first run of junction lanes (from an
    ``ir*`` node), or None when it crosses no junction."""
    inside = [lane[0].startswith(JUNCTION_PREFIX) for lane in route.lanes]
    if not any(inside):
        return None
    first = inside.index(True)
    last = first
    while last + 1 < len(inside) and inside[last + 1]:
        last += 1
    return float(route.offsets[first]), float(route.offsets[last] + route.lengths[last])
