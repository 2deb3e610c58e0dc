r"""A predictor that knows highway-env's road: one mode per route, moving along the lanes.

:class:`LanePredictor` (``name = "lane"``) maps a road user's measurement $(x, y, \theta, v,
\omega)$ to a :class:`~risk_env.prediction.mixture.Mixture` over $n = 0, \dots, N$, reading only the road
network (never a vehicle's route, destination or target lane):

- **Routes** (:mod:`~risk_env.highway.lanes.routes`): the lanes the road user is on (the one
  highway-env's ``get_closest_lane_index`` gives for its position and direction of travel, and
  every lane that holds it within its length and width in a heading less than 90 degrees off: a
  vehicle entering a junction lies on all its turns), and every route through the graph from
  there, up to its first fork (``lookahead``) and as far as it can drive within the horizon.
- **Modes**: routes that share every lane the road user can reach within the horizon (at full
  acceleration up to the speed limit) are one mode, so a vehicle far from a junction has one mode,
  one that can reach it has one per turn, and one inside a turn has one.
- **Weights** (:mod:`~risk_env.highway.lanes.weights`): a prior over the turns times the likelihood
  of the observed lateral offset, heading and turn rate against each route; a mode's weight is the
  sum of its routes' (:attr:`LaneMode.routes`).
- **Means** (:mod:`~risk_env.highway.lanes.speed`): each route moves along its centreline with
  highway-env's IDM behind the leader found as highway-env finds it and its intersection's
  yielding rule, every road user of the scene together (:meth:`LanePredictor.predict_scene`); the
  lateral offset decays to the centreline. A mode's mean is the weighted mean of its routes'.
- **Spread** (:mod:`~risk_env.highway.lanes.beliefs`), in the lane's frame (the belief's ``frame``:
  the route's heading at the mode's mean, or at the middle of its reachable stretch): along the lane
  the truncation box reaches from full braking (``a_max``, to a stop) to full acceleration up to the
  speed limit, and at least to every route's own mean, plus ``margin_along``; it is the box around
  the mean that holds the centreline between those two ends (on a curve it widens across the lane to
  hold the arc) plus ``margin_across``. The standard deviation along is
  $\sqrt{\sigma_{along,0}^2 + (\sigma_v t)^2 + (\sigma_a t^2 / 2)^2}$ at time $t$ (at most the box),
  across $\sigma_{across}$ (at most the box, and at most half the lane's width); the speed's is
  $\sigma_v + \sigma_a t$ (:class:`~risk_env.highway.lanes.beliefs.Spread`) within the speeds of
  full braking and full acceleration.
- **Interval prediction** (``longitudinal="interval"``, name ``"lane+interval"``;
  :mod:`~risk_env.highway.lanes.interval`): along the lane the box reaches instead from the slow to
  the fast run of highway-env's IDM over its parameter box (the exponent's range, the desired
  speed), every road user together, within the full range; with ``ego`` the ego takes part as a
  leader and as a road user to yield to.
- **Off the road**: a road user farther than ``off_road`` [m] from every lane (beside it, or
  before its start or beyond its end) is predicted by ``fallback`` (the paper's constant predictor,
  one mode) and counted in :attr:`LanePredictor.fallbacks`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from risk_env import checks
from risk_env.highway.common import SPEED_BOUND
from risk_env.highway.lanes.beliefs import Spread
from risk_env.highway.lanes.hypotheses import (
    EgoPlan,
    Hypotheses,
    Scene,
    agents_of,
    per_user,
    planned,
    turn_signal,
)
from risk_env.highway.lanes.interval import (
    LONGITUDINAL,
    IntervalModel,
    interval_bounds,
    lane_only,
)
from risk_env.highway.lanes.modes import LaneMode, lane_mixture  # noqa: F401 (LaneMode: exported here too)
from risk_env.highway.lanes.routes import Route, check_lane, lane_distance, next_lanes, routes_from, wrap
from risk_env.highway.lanes.speed import SpeedModel, TrafficModel, reach
from risk_env.highway.lanes.table import ON_LANE_MARGIN
from risk_env.highway.lanes.weights import WeightModel, route_weights, turn_of
from risk_env.prediction.mixture import Mixture
from risk_env.prediction.predictors import ConstantPredictor, Predictor
from risk_env.scenario.scenario import Scenario

ORDER = ("straight", "left", "right")
"""The order of a road user's modes by turn: of equally likely modes the first is the most likely
one (:meth:`Mixture.most_likely <risk_env.prediction.mixture.Mixture.most_likely>`), and straight on
lies between the turns."""


class LanePredictor(Predictor):
    """Routes along highway-env's lanes as modes (see the module docstring).

    Args:
        road_network: highway-env's ``RoadNetwork`` (``env.unwrapped.road.network``), read at each
            prediction (a new episode builds a new one with the same geometry).
        dt: the prediction step [s] (the env's step, :func:`risk_env.highway.policy_period`).
        traffic: the speed model's numbers (:class:`~risk_env.highway.lanes.speed.TrafficModel`).
        weights: the route weights' numbers (:class:`~risk_env.highway.lanes.weights.WeightModel`).
        lookahead: how far ahead [m] routes are followed to their first fork, whatever the horizon.
        off_road: farther than this [m] from every lane, a road user goes to ``fallback``.
        spread: the beliefs' spread (:class:`~risk_env.highway.lanes.beliefs.Spread`).
        fallback: the predictor of road users off the road (default: the paper's constant
            predictor at the ``low`` level with speeds up to 40 m/s, as
            :func:`risk_env.highway.highway_scenario`).
        pieces: P, each route's stretch along the lane split into P bands, one mode each.
        longitudinal: ``"reach"`` (full braking to full acceleration) or ``"interval"`` (the IDM
            over its parameter box, :mod:`~risk_env.highway.lanes.interval`; the predictor's
            :attr:`name` is then ``"lane+interval"``).
        intervals: the interval prediction's numbers
            (:class:`~risk_env.highway.lanes.interval.IntervalModel`; ``"interval"`` only).
        ego: ``"interval"`` only: a callable returning the ego's measurement ``(5,)`` (or None) at
            each prediction: the ego takes part in the scene (a leader, a road user to yield to).
    """

    name = "lane"

    def __init__(
        self,
        road_network: Any,
        dt: float,
        traffic: TrafficModel | None = None,
        weights: WeightModel | None = None,
        spread: Spread | None = None,
        lookahead: float = 150.0,
        off_road: float = 2.0,
        fallback: Predictor | None = None,
        pieces: int = 1,
        longitudinal: str = "reach",
        intervals: IntervalModel | None = None,
        ego: Callable[[], Any] | None = None,
    ) -> None:
        if not (hasattr(road_network, "graph") and hasattr(road_network, "get_closest_lane_index")):
            raise TypeError(
                f"road_network must be highway-env's RoadNetwork, got {checks.describe(road_network)}"
            )
        if not road_network.lanes_list():
            raise ValueError("road_network has no lanes")
        self.network = road_network
        self.dt = checks.positive("dt", dt)
        self.traffic = TrafficModel() if traffic is None else traffic
        self.weights = WeightModel() if weights is None else weights
        self.spread = Spread() if spread is None else spread
        for name, value, kind in (
            ("traffic", self.traffic, TrafficModel),
            ("weights", self.weights, WeightModel),
            ("spread", self.spread, Spread),
        ):
            if not isinstance(value, kind):
                raise TypeError(f"{name} must be a {kind.__name__} or None, got {checks.describe(value)}")
        self.lookahead = checks.positive("lookahead", lookahead)
        self.off_road = checks.positive("off_road", off_road)
        self.pieces = checks.integer("pieces", pieces, minimum=1)
        """P: each route's reachable stretch is split into P bands, one mode each."""
        self.max_modes = len(ORDER) * self.pieces
        if fallback is None:
            scenario = Scenario.preset("low", dt=self.dt, velocity_bounds0=(-SPEED_BOUND, SPEED_BOUND))
            fallback = ConstantPredictor(scenario)
        if not isinstance(fallback, Predictor):
            raise TypeError(f"fallback must be a Predictor, got {checks.describe(fallback)}")
        self.fallback = fallback
        self.longitudinal = checks.text("longitudinal", longitudinal, LONGITUDINAL)
        if longitudinal == "interval":
            self.name = "lane+interval"
        elif intervals is not None or ego is not None:
            raise ValueError(
                f"intervals and ego need longitudinal='interval', got longitudinal={longitudinal!r}"
            )
        self.intervals = IntervalModel() if intervals is None else intervals
        if not isinstance(self.intervals, IntervalModel):
            raise TypeError(f"intervals must be an IntervalModel or None, got {checks.describe(intervals)}")
        if ego is not None and not callable(ego):
            raise TypeError(
                f"ego must be a callable returning a measurement, or None, got {checks.describe(ego)}"
            )
        self.ego = ego
        if longitudinal == "interval" and self.intervals.split_yield:
            self.max_modes *= 2  # held and free
        self.speed_model = SpeedModel(road_network, self.traffic)
        self._lane_model = lane_only(self.speed_model) if longitudinal == "interval" else None
        self._routes: dict[tuple, Route] = {}
        self._turns: dict[tuple, str] = {}
        self._next: dict[tuple, list] = {}
        self.fallbacks = 0
        """How many road users were off the road and went to ``fallback``, since construction."""
        self.predicted = 0
        """How many road users were predicted, since construction."""

    def __repr__(self) -> str:
        extra = f", intervals={self.intervals}" if self.longitudinal == "interval" else ""
        return f"LanePredictor(dt={self.dt}, traffic={self.traffic}, weights={self.weights}{extra})"

    # ------------------------------------------------------------------ interface
    def predict(self, measurement: Any, steps: int, lane: Any = None, signal: Any = None) -> Mixture:
        """The mixture of one road user alone (no leader, nobody to yield to); ``lane``: its lane
        index if known (checked against the map; it then stands for the closest lane, and the road
        user counts as on the road), ``signal``: its turn signal (a unit vector toward its
        destination, highway-env's ``observe_intentions``) if observed."""
        m = np.asarray(checks.finite_reals("measurement", measurement, 5), dtype=float)
        return self.predict_scene(
            m[None],
            steps,
            lanes=None if lane is None else [lane],
            signals=None if signal is None else [signal],
        )[0]

    def predict_scene(
        self,
        measurements: Any,
        steps: int,
        lanes: Any = None,
        signals: Any = None,
        ego_plan: EgoPlan | None = None,
    ) -> list[Mixture]:
        """One mixture per road user of ``measurements (m, 5)``, all moved together (leaders,
        yielding). ``lanes``: None, or one lane index (or None) per road user; ``signals``: None, or
        one turn signal ``(2,)`` (or None) per road user. ``ego_plan``: with the interval prediction
        and an ``ego``, the prediction given that the ego drives so (:class:`EgoPlan`: on its
        route, never yielding, the others reacting to it as highway-env's traffic does) instead of
        braking."""
        scene = self.scene(measurements, steps, lanes, signals, ego_plan)
        agents, is_ego, motion = scene.agents, scene.is_ego, scene.motion
        s, v = (
            self.speed_model.run(
                agents,
                steps,
                self.dt,
                scripted=is_ego if motion else None,
                script=motion,
                exempt=is_ego if motion else None,
            )
            if len(agents.vehicle)
            else (None, None)
        )
        bounds = None
        if self.longitudinal == "interval" and len(agents.vehicle):
            bounds = interval_bounds(
                self.speed_model,
                agents,
                steps,
                self.dt,
                self.intervals,
                (s, v),
                is_ego,
                self._lane_model,
                motion,
            )
        out: list[Mixture] = []
        first = 0
        self.predicted += scene.users
        for row, hyp in zip(scene.rows[: scene.users], scene.hypotheses[: scene.users], strict=True):
            if hyp is None:
                self.fallbacks += 1
                out.append(self.fallback.predict(row, steps))
                continue
            part = slice(first, first + len(hyp.routes))
            out.append(
                lane_mixture(self, row, hyp, s[part], v[part], None if bounds is None else bounds.part(part))
            )
            first += len(hyp.routes)
        return out

    def scene(
        self,
        measurements: Any,
        steps: int,
        lanes: Any = None,
        signals: Any = None,
        ego_plan: EgoPlan | None = None,
    ) -> Scene:
        """Every road user's route hypotheses as the speed model's agents, the ego's among them
        when the predictor has one (see :meth:`predict_scene`, whose arguments these are)."""
        rows = np.asarray(measurements, dtype=float)
        if rows.ndim != 2 or rows.shape[1] != 5 or not np.all(np.isfinite(rows)):
            raise ValueError(
                f"measurements must be finite, of shape (m, 5), got {checks.describe(measurements)}"
            )
        steps = checks.integer("steps", steps, minimum=0)
        lanes, signals = per_user("lanes", lanes, len(rows)), per_user("signals", signals, len(rows))
        users = len(rows)
        ego = None if self.ego is None else self.ego()
        if ego is not None:  # the ego takes part in the scene, predicted for nobody
            ego = np.asarray(checks.finite_reals("the ego's measurement", ego, 5), dtype=float)
            rows, lanes, signals = np.vstack([rows, ego]), [*lanes, None], [*signals, None]
        lanes = [None if lane is None else check_lane(self.network, lane) for lane in lanes]
        along, across = self.speed_model.table.locate(rows[:, :2])
        hypotheses = [
            self._hypotheses(row, steps, lane, turn_signal(signal), along[:, i], across[:, i])
            for i, (row, lane, signal) in enumerate(zip(rows, lanes, signals, strict=True))
        ]
        if ego is not None and ego_plan is not None and hypotheses[-1] is not None:
            hypotheses[-1] = planned(hypotheses[-1], ego_plan)
        motion = None if ego is None or ego_plan is None else (float(ego_plan.accel), float(ego_plan.speed))
        agents = agents_of(rows, hypotheses)
        is_ego = agents.vehicle == users if ego is not None else np.zeros(len(agents.vehicle), dtype=bool)
        return Scene(rows, users, hypotheses, agents, is_ego, motion)

    # ------------------------------------------------------------------ hypotheses
    def _route(self, lanes: tuple) -> Route:
        """The route through ``lanes`` (built once per predictor), its turn noted in ``_turns``."""
        route = self._routes.get(lanes)
        if route is None:
            route = self._routes[lanes] = Route(self.network, lanes)
            self._turns[lanes] = turn_of(route)
        return route

    def _start_lanes(
        self, point: np.ndarray, theta: float, lane: Any, s: np.ndarray, r: np.ndarray
    ) -> list[tuple[str, str, int]]:
        """The lanes the road user is on: the closest (or ``lane``) and every lane that holds
        ``point`` within its length and width in a heading less than 90 degrees from ``theta``
        (``s``, ``r``: its coordinates on every lane of :attr:`table`); [] when it is off the road."""
        table = self.speed_model.table
        if lane is None:
            closest = table.indices[int(table.closest(s[:, None], r[:, None], np.array([theta]))[0])]
        else:
            closest = lane
        if lane is None and lane_distance(self.network.get_lane(closest), point) > self.off_road:
            return []
        out = [closest]
        half = table.half_width - ON_LANE_MARGIN
        for i in np.flatnonzero((s >= 0) & (s <= table.length) & (np.abs(r) <= half)):
            index = table.indices[i]
            if index != closest and abs(float(wrap(theta - table.objects[i].heading_at(s[i])))) < math.pi / 2:
                out.append(index)
        return out

    def _following(self, index: tuple[str, str, int]) -> list[tuple[str, str, int]]:
        """:func:`~risk_env.highway.lanes.routes.next_lanes`, once per lane."""
        if index not in self._next:
            self._next[index] = next_lanes(self.network, index)
        return self._next[index]

    def _hypotheses(
        self, row: np.ndarray, steps: int, lane: Any, signal: np.ndarray | None, s: np.ndarray, r: np.ndarray
    ) -> Hypotheses | None:
        point, theta, v = row[:2], float(row[2]), float(row[3])
        starts = self._start_lanes(point, theta, lane, s, r)
        if not starts:
            return None
        limit = self.network.get_lane(starts[0]).speed_limit
        limit = SPEED_BOUND if limit is None else float(limit)
        furthest = float(reach(v, limit, steps, self.dt, self.traffic.max_acceleration)[1][-1])
        routes: dict[tuple, Route] = {}
        for index in starts:
            s0, _ = self.network.get_lane(index).local_coordinates(point)
            for lanes in routes_from(
                self.network, index, float(s0), furthest, self.lookahead, self._following
            ):
                route = self._route(lanes)
                here = int(route.lane_of(route.locate(point)[0]))  # from the lane it is on now
                route = self._route(lanes[here:])
                routes.setdefault(route.lanes, route)
        chosen = sorted(routes.values(), key=lambda route: ORDER.index(self._turns[route.lanes]))
        located = np.array([route.locate(point) for route in chosen])
        turns = [self._turns[route.lanes] for route in chosen]
        weights = route_weights(self.weights, chosen, turns, row, signal)
        groups: dict[tuple, list[int]] = {}
        for k, (route, s0) in enumerate(zip(chosen, located[:, 0], strict=True)):
            # the lanes it can reach: up to the one at full acceleration (at least the one it is on,
            # also when it rolls backwards)
            reached = route.lanes[: int(route.lane_of(s0 + max(furthest, 0.0))) + 1]
            groups.setdefault(reached, []).append(k)
        labels = [">".join([key[0][0], *(index[1] for index in key)]) for key in groups]
        return Hypotheses(chosen, located[:, 0], located[:, 1], weights, list(groups.values()), labels)
