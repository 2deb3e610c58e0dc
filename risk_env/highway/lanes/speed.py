r"""The lane predictor's speed model: highway-env's own traffic rules, run along route hypotheses.

Each road user's route hypothesis (an *agent*: one vehicle on one
:class:`~risk_env.highway.lanes.routes.Route`) moves along its route's centreline with the
longitudinal model of highway-env's ``IDMVehicle`` (``vehicle/behavior.py``) and the yielding rule
of its ``RegulatedRoad`` (``road/regulation.py``), with the numbers of :class:`TrafficModel` (those
``intersection-v2`` gives its traffic):

- **IDM**: $a = A (1 - (\max(v, 0) / v_0)^\delta) - A (d^* / d)^2$,
  $d^* = d_0 + v \tau + v\, \Delta v / (2 \sqrt{A B})$, clipped to $\pm a_{max}$; $d$ and $\Delta v$
  come from the leader, found as
  highway-env's ``Road.neighbour_vehicles`` finds it: among the other road users on the agent's
  lane, and (``connected_lanes``, highway-env 1.12's ``neighbour_vehicles_connected_lanes``, on in
  ``intersection-v2``) on every lane the graph connects before or after it. That rule also takes a
  vehicle on the approach lane beside an exit lane as the leader of a vehicle on that exit (the
  graph joins the exit's end node to that approach lane), which is why exits see vehicles brake
  and roll backwards; the model brakes the same way.
- **Yielding**: every ``regulation_period`` (from the measurement on), two road users whose
  constant-speed futures along their routes overlap within ``conflict_horizon`` (rectangles of
  1.5 x length by 0.9 x width, highway-env's ``rotated_rectangles_intersect`` vectorised in
  :func:`~risk_env.highway.lanes.routes.rectangles_intersect`)
  are in conflict; the one on the lane of lower ``priority`` (equal: the one behind) yields, its
  desired speed set to 0 until the next check, and to its lane's speed limit after it.
- **Desired speed** v0 is not observed: ``max(v, cruise_speed)``, capped by the lane's limit.

The other road users are represented by one agent each (their most likely route); the modes of a
road user that are not its most likely one react to them, but nobody reacts to those modes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from risk_env.highway.lanes.routes import Route, interpolate, rectangles_intersect
from risk_env.highway.lanes.table import LaneTable

NOT_ZERO = 1e-2
"""highway-env's ``utils.not_zero`` floor."""


@dataclass(frozen=True)
class TrafficModel:
    """The numbers of the speed model (see the module docstring); defaults: highway-env's
    ``IDMVehicle`` as ``intersection-v2`` sets it and its ``RegulatedRoad``."""

    comfort_acceleration: float = 6.0
    """$A$ [m/s²], ``IDMVehicle.COMFORT_ACC_MAX`` (``intersection-v2`` sets 6)."""
    comfort_deceleration: float = 3.0
    """$B$ [m/s²], ``-IDMVehicle.COMFORT_ACC_MIN`` (``intersection-v2`` sets -3)."""
    max_acceleration: float = 6.0
    r"""$a_{max}$ [m/s²], ``IDMVehicle.ACC_MAX``: the acceleration is clipped to $\pm$ this."""
    distance_wanted: float = 7.0
    """$d_0$ [m], ``IDMVehicle.DISTANCE_WANTED`` (``intersection-v2`` sets 7)."""
    time_wanted: float = 1.5
    r"""$\tau$ [s], ``IDMVehicle.TIME_WANTED``."""
    delta: float = 4.0
    r"""The IDM exponent $\delta$ (highway-env draws it in [3.5, 4.5] per vehicle)."""
    cruise_speed: float = 7.5
    r"""Desired speed [m/s] assumed for a road user slower than this (highway-env's traffic enters
    at $8 \pm 1$ m/s and keeps that speed as its target until it first yields, then the lane's limit).
    7.5 gave the smallest 3 s error on the benchmark's first episodes (seeds 0-11; tried 0, i.e.
    the speed itself, 6, 7, 7.5, 7.75, 8, 8.5 and 10)."""
    connected_lanes: bool = True
    """Search leaders on connected lanes too (highway-env 1.12's ``neighbour_vehicles_connected_lanes``,
    on in ``intersection-v2``, off in ``-v1``)."""
    yielding: bool = True
    """Apply the regulation's yielding rule."""
    regulation_period: float = 0.5
    """Time [s] between two checks of the yielding rule (``1 / RegulatedRoad.REGULATION_FREQUENCY``)."""
    conflict_horizon: float = 3.0
    """How far ahead [s] the yielding rule looks (``is_conflict_possible``'s horizon)."""
    conflict_step: float = 0.25
    """Its time step [s]."""
    vehicle_length: float = 5.0
    """Length [m] of a road user (highway-env's ``Vehicle.LENGTH``)."""
    vehicle_width: float = 2.0
    """Width [m] of a road user (highway-env's ``Vehicle.WIDTH``)."""
    lateral_time: float = 0.6
    """Time constant [s] with which a lateral offset from the centreline decays
    (``ControlledVehicle.TAU_LATERAL``)."""
    substeps: int = 4
    """Integration steps per prediction step."""

    def __post_init__(self) -> None:
        for name in (
            "comfort_acceleration",
            "comfort_deceleration",
            "max_acceleration",
            "regulation_period",
            "conflict_horizon",
            "conflict_step",
            "vehicle_length",
            "vehicle_width",
            "lateral_time",
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"TrafficModel.{name} must be a finite number > 0, got {value!r}")
        for name in ("distance_wanted", "time_wanted", "delta", "cruise_speed"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"TrafficModel.{name} must be a finite number >= 0, got {value!r}")
        if isinstance(self.substeps, bool) or not isinstance(self.substeps, int) or self.substeps < 1:
            raise ValueError(f"TrafficModel.substeps must be an integer >= 1, got {self.substeps!r}")


@dataclass
class Agents:
    """Route hypotheses to move together: agent a is road user ``vehicle[a]`` on ``routes[a]``."""

    vehicle: np.ndarray
    """``(A,)`` int: the road user of each agent."""
    routes: list[Route]
    """The agents' routes."""
    s: np.ndarray
    """``(A,)`` arc length [m] on the route."""
    r: np.ndarray
    """``(A,)`` lateral offset [m] from the centreline."""
    v: np.ndarray
    """``(A,)`` speed [m/s] along the route."""
    representative: np.ndarray
    """``(A,)`` bool: the agent stands for its road user in others' eyes (one per road user)."""
    weight: np.ndarray | None = None
    """``(A,)`` the weight of each agent's route among its road user's (summing to 1 per road
    user); None: all 1 (what :meth:`SpeedModel.run` needs only for its ``yields`` output)."""


def _found(
    table: LaneTable, lane: np.ndarray, coords: np.ndarray, on: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where each of B road users lies on the lanes ``table`` searches from each agent's ``lane``
    ``(A,)``: its arc length ``(A, B)`` [m] on the first searched lane it is on, put on the agent's
    lane, and whether it is on any; from its coordinates ``coords`` and ``on`` ``(L, B)``."""
    search = table.search[lane]  # (A, J)
    on_search = on[np.maximum(search, 0)] & (search >= 0)[:, :, None]  # (A, J, B)
    first = np.argmax(on_search, axis=1)  # (A, B): the first lane each one is on
    hit = np.take_along_axis(search, first, axis=1)
    s_v = coords[np.maximum(hit, 0), np.arange(on.shape[1])[None, :]]
    return s_v + np.take_along_axis(table.search_offset[lane], first, axis=1), on_search.any(axis=1)


def _not_zero(x: np.ndarray) -> np.ndarray:
    return np.where(np.abs(x) > NOT_ZERO, x, np.where(x >= 0, NOT_ZERO, -NOT_ZERO))


class SpeedModel:
    """Moves :class:`Agents` over the horizon with a :class:`TrafficModel` (module docstring)."""

    def __init__(
        self, network: Any, model: TrafficModel, table: LaneTable | None = None, wide: LaneTable | None = None
    ) -> None:
        self.network = network
        self.model = model
        self.table = LaneTable(network, model.connected_lanes) if table is None else table
        """The lanes' table (``table``: another leader search than ``model.connected_lanes``)."""
        self.wide = wide
        """The table whose wider search finds the leaders :meth:`run` is told to seek on it (``wide``),
        or None."""

    def run(
        self,
        agents: Agents,
        steps: int,
        dt: float,
        delta: float | np.ndarray | None = None,
        target: np.ndarray | None = None,
        yielding: bool | None = None,
        partners: np.ndarray | None = None,
        scripted: np.ndarray | None = None,
        script: tuple[float, float] | None = None,
        exempt: np.ndarray | None = None,
        yields: np.ndarray | None = None,
        yield_to: np.ndarray | None = None,
        wide: np.ndarray | None = None,
        script_follows: bool = False,
    ) -> tuple[np.ndarray, np.ndarray]:
        r"""Arc lengths and speeds ``(A, steps+1)`` of every agent at n = 0..steps (step ``dt`` [s]).
        By default with the model's numbers; the interval prediction sets, per agent, the IDM's
        ``delta`` and the initial desired speed ``target`` [m/s] (capped by the lane's limit; default
        the speed, at least the cruise speed), whether anyone ``yielding`` follows the regulation's
        rule, the ``partners`` (indices) that lead and are yielded to (default the representatives)
        and the agents ``scripted`` (``(A,)`` bool) that follow no IDM: at full braking to a stop, or
        with ``script`` ``(a, v)`` accelerating at a [m/s²] up to v [m/s] (the ego, as it plans).
        ``exempt`` ``(A,)`` bool: agents that never yield (highway-env's rule leaves the controlled
        vehicle alone); whether others yield to them is as for anyone (``partners``). ``yields``: an
        ``(A,)`` float array, filled with the probability that each agent yields at the first check
        at which it yields in this run (0 where it never does): one minus the chance, over the road
        users it yields to, that none of them is on a route it yields to (their routes'
        :attr:`Agents.weight`, independent). ``yield_to`` ``(A,)`` bool: the agents yielded to under
        the rule (default the partners). ``wide`` ``(A,)`` bool: leaders sought on :attr:`wide`'s
        lanes (ignored without that table). ``script_follows``: the agents with a ``script`` still
        brake for their leader as the IDM would (an ego that goes and does not drive into anyone)."""
        m, table = self.model, self.table
        count = len(agents.vehicle)
        samples = stack_samples([route.samples for route in agents.routes])
        depth = max(len(route.lanes) for route in agents.routes)
        offsets = np.full((count, depth), np.inf)
        lane_ids = np.zeros((count, depth), dtype=int)
        for a, route in enumerate(agents.routes):
            offsets[a, : len(route.lanes)] = route.offsets
            lane_ids[a, : len(route.lanes)] = [table.id[index] for index in route.lanes]
        s, v = agents.s.astype(float).copy(), agents.v.astype(float).copy()
        rows = np.arange(count)
        which = np.maximum((s[:, None] >= offsets).sum(axis=1) - 1, 0)
        wanted = np.maximum(v, m.cruise_speed) if target is None else target
        target = np.minimum(wanted, table.limit[lane_ids[rows, which]])
        yielded = np.zeros(count, dtype=bool)
        s_out, v_out = np.empty((count, steps + 1)), np.empty((count, steps + 1))
        s_out[:, 0], v_out[:, 0] = s, v
        h = dt / m.substeps
        ticks = max(int(round(m.regulation_period / h)), 1)
        reps = np.flatnonzero(agents.representative) if partners is None else partners
        yielding = m.yielding if yielding is None else yielding
        yielded_to = reps if yield_to is None else np.flatnonzero(yield_to)
        if yields is not None:
            yields[:] = 0.0
        for k in range(steps * m.substeps):
            which = np.maximum((s[:, None] >= offsets).sum(axis=1) - 1, 0)
            lane = lane_ids[rows, which]
            local = s - offsets[rows, which]
            xyh = interpolate(samples, s)
            heading = xyh[:, 2]
            normal = np.column_stack([-np.sin(heading), np.cos(heading)])
            points = xyh[:, :2] + (agents.r * math.exp(-k * h / m.lateral_time))[:, None] * normal
            if yielding and k % ticks == 0:
                now, chance = self._yielders(agents, samples, s, v, points, heading, lane, yielded_to)
                if exempt is not None:
                    now, chance = now & ~exempt, np.where(exempt, 0.0, chance)
                if yields is not None:
                    yields[:] = np.where(yields > 0, yields, chance)
                target = np.where(now, 0.0, np.where(yielded, table.limit[lane], target))
                yielded = now
            acceleration = self._idm(agents, v, target, points, heading, lane, local, reps, delta, wide)
            if scripted is not None:
                if script is None:  # full braking to a stop
                    forced = np.maximum(-m.max_acceleration, (np.minimum(v, 0.0) - v) / h)
                else:
                    forced = np.clip((script[1] - v) / h, -m.max_acceleration, script[0])
                    forced = np.minimum(forced, acceleration) if script_follows else forced
                acceleration = np.where(scripted, forced, acceleration)
            s = s + v * h
            v = v + acceleration * h
            if (k + 1) % m.substeps == 0:
                s_out[:, (k + 1) // m.substeps], v_out[:, (k + 1) // m.substeps] = s, v
        return s_out, v_out

    def _idm(
        self,
        agents: Agents,
        v: np.ndarray,
        target: np.ndarray,
        points: np.ndarray,
        heading: np.ndarray,
        lane: np.ndarray,
        local: np.ndarray,
        reps: np.ndarray,
        delta: float | np.ndarray | None = None,
        wide: np.ndarray | None = None,
    ) -> np.ndarray:
        """highway-env's ``IDMVehicle.acceleration`` of every agent behind its leader (``delta``: the
        exponent, per agent or the model's; ``wide``: see :meth:`run`)."""
        m, table = self.model, self.table
        count = len(v)
        coords, on = table.coordinates(points[reps])  # (L, B); the same lanes in every table
        s_v, anywhere = _found(table, lane, coords, on)
        if wide is not None and self.wide is not None and wide[reps].any():
            s_wide, any_wide = _found(self.wide, lane, coords, on)
            s_v = np.where(wide[reps][None, :], s_wide, s_v)
            anywhere = np.where(wide[reps][None, :], any_wide, anywhere)
        candidate = (
            anywhere & (agents.vehicle[reps][None, :] != agents.vehicle[:, None]) & (s_v >= local[:, None])
        )
        has = candidate.any(axis=1)
        leader = np.argmin(np.where(candidate, s_v, np.inf), axis=1)  # index into reps
        direction = np.column_stack([np.cos(heading), np.sin(heading)])
        gap = coords[lane, leader] - local
        rows = np.arange(count)
        ahead = reps[leader]
        closing = np.einsum("ij,ij->i", v[:, None] * direction - v[ahead, None] * direction[ahead], direction)
        wanted = np.clip(target, 0.0, table.limit[lane])
        acceleration = m.comfort_acceleration * (
            1 - np.power(np.maximum(v, 0.0) / np.abs(_not_zero(wanted)), m.delta if delta is None else delta)
        )
        d_star = (
            m.distance_wanted
            + v * m.time_wanted
            + v * closing / (2 * math.sqrt(m.comfort_acceleration * m.comfort_deceleration))
        )
        interaction = m.comfort_acceleration * np.power(d_star / _not_zero(gap), 2)
        acceleration = acceleration - np.where(has[rows], interaction, 0.0)
        return np.clip(acceleration, -m.max_acceleration, m.max_acceleration)

    def _yielders(
        self,
        agents: Agents,
        samples: np.ndarray,
        s: np.ndarray,
        v: np.ndarray,
        points: np.ndarray,
        heading: np.ndarray,
        lane: np.ndarray,
        reps: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Which agents yield under the regulation's rule (module docstring) ``(A,)`` bool, and the
        probability of it ``(A,)`` (see :meth:`run`'s ``yields``)."""
        m = self.model
        times = np.arange(m.conflict_step, m.conflict_horizon, m.conflict_step)
        future = interpolate(samples, s[:, None] + v[:, None] * times[None, :])  # (A, T, 3)
        priority = self.table.priority[lane]
        direction = np.column_stack([np.cos(heading), np.sin(heading)])
        other = agents.vehicle[reps][None, :] != agents.vehicle[:, None]  # (A, B)
        gap = points[reps][None, :, :] - points[:, None, :]  # (A, B, 2)
        behind = np.einsum("ad,abd->ab", direction, gap) > np.einsum("bd,abd->ab", direction[reps], -gap)
        lower = (priority[:, None] < priority[reps][None, :]) | (
            (priority[:, None] == priority[reps][None, :]) & behind
        )
        close = (
            np.hypot(*(future[:, None, :, :2] - future[reps][None, :, :, :2]).transpose(3, 0, 1, 2))
            <= m.vehicle_length
        )
        possible = close & (other & lower)[:, :, None]
        a, b, i = np.nonzero(possible)
        hit = rectangles_intersect(
            future[a, i, :2],
            future[a, i, 2],
            future[reps[b], i, :2],
            future[reps[b], i, 2],
            1.5 * m.vehicle_length,
            0.9 * m.vehicle_width,
        )
        out = np.zeros(len(s), dtype=bool)
        out[a[hit]] = True
        # the mass of each (agent, road user yielded to) pair's conflicting routes, counted once per route
        weight = np.ones(len(s)) if agents.weight is None else agents.weight
        pairs = np.unique(np.column_stack([a[hit], reps[b[hit]]]), axis=0)
        users = agents.vehicle[pairs[:, 1]] if len(pairs) else np.zeros(0, dtype=int)
        mass = np.zeros((len(s), int(agents.vehicle.max(initial=0)) + 1))
        np.add.at(mass, (pairs[:, 0], users), weight[pairs[:, 1]])
        chance = 1.0 - np.prod(1.0 - np.clip(mass, 0.0, 1.0), axis=1)
        return out, np.where(out, chance, 0.0)


def stack_samples(samples: list[np.ndarray]) -> np.ndarray:
    """Route samples of different lengths as one ``(A, K, 3)`` array, each padded by its last row."""
    size = max(len(x) for x in samples)
    return np.stack([np.concatenate([x, np.repeat(x[-1:], size - len(x), axis=0)]) for x in samples])


def reach(v: float, limit: float, steps: int, dt: float, a_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Displacements [m] ``(steps+1,)`` at n = 0..steps from full braking (``a_max`` [m/s^2] down to
    a stop, or to ``v`` if it is negative) and from full acceleration (up to ``limit``, or ``v`` if
    faster)."""
    t = np.arange(steps + 1) * dt
    floor = min(v, 0.0)
    t_stop = max(v - floor, 0.0) / a_max
    low = np.where(
        t < t_stop, v * t - a_max * t**2 / 2, (v * t_stop - a_max * t_stop**2 / 2) + floor * (t - t_stop)
    )
    top = max(limit, v)
    t_top = max(top - v, 0.0) / a_max
    high = np.where(
        t < t_top, v * t + a_max * t**2 / 2, (v * t_top + a_max * t_top**2 / 2) + top * (t - t_top)
    )
    return low, high
