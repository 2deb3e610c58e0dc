r"""Interval prediction over highway-env's IDM parameters: bounds on a route hypothesis's arc length
and speed at n = 0..N, for the lane predictor's ``longitudinal="interval"`` (``"lane+interval"``).

highway-env's traffic (``IDMVehicle`` as ``intersection-v2`` sets it) draws one IDM parameter per
vehicle, the exponent $\delta$ uniformly in ``DELTA_RANGE`` = [3.5, 4.5]
(``randomize_behavior``); its desired speed is its speed at spawn (``target_speed``), set to the
lane's limit when it stops yielding and to 0 while it yields; $A$, $B$, $d_0$, $\tau$ and the clip
$a_{max}$ are the class's own numbers. Following Leurent's interval predictor
(``highway_env.vehicle.uncertainty.prediction.IntervalVehicle``), which propagates the state
interval through the IDM with its parameters in a box, each road user's routes are moved twice,
every road user of the scene together (the speed model of :mod:`~risk_env.highway.lanes.speed`):

- **fast** (the upper bound): $\delta$ at the top of its range and the desired speed at the lane's
  limit (while $v \le v_0$ the IDM's free term grows with both), behind the leaders' fast
  futures on the road user's own lane only: highway-env's search on connected lanes also takes an
  oncoming vehicle on the approach beside an exit (or the exit beside an approach) for a leader,
  at its coordinate on the follower's lane, and a vehicle spawned at the approach's start then
  replaces it by one far away, which no prediction sees coming, so the upper bound does without
  those leaders; nobody yields (:attr:`IntervalModel.upper_yields` False), unless asked to apply
  the regulation's rule as the mean does; the ego (when the predictor is given one) brakes fully
  (:attr:`IntervalModel.ego_leads`), so that no box of a road user behind it reaches through it;
- **slow** (the lower bound): $\delta$ at the bottom of its range and the desired speed at the
  measured speed (a vehicle that does not yield never wants less than it drives), behind the
  nearest of every route hypothesis of every other road user, and yielding to any of them under
  the regulation's rule; the ego (when the predictor is given one) brakes fully.

The IDM's acceleration grows with the leader's position and speed and falls with the follower's
own position, so a follower behind its leader's upper (lower) future tends to stay at or below
(above) its own upper (lower) one. These are not guaranteed bounds: the IDM is not monotone in the
follower's own speed, the yielding rule is a discrete decision on constant-speed futures, and
vehicles spawn; the prediction benchmark measures how often they hold. The bounds on each step are
the runs' and the mean's extremes widened by ``margin_rate`` times the time (the regulation's check
phase, 0.5 s, is not observed, nor is the simulation's 1/16 s step), clipped to the lane
predictor's full range (full braking to full acceleration), so that along the lane an interval box
lies within the full-range one; across a curving route the box widens by ``margin_turn``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from risk_env.highway.lanes.speed import Agents, SpeedModel
from risk_env.highway.lanes.table import LaneTable

LONGITUDINAL = ("reach", "interval")
"""How the lane predictor bounds a mode along its route: ``"reach"`` (full braking to full
acceleration) or ``"interval"`` (this module)."""


@dataclass(frozen=True)
class IntervalModel:
    """The parameter intervals and margins of the interval prediction (module docstring)."""

    delta: tuple[float, float] = (3.5, 4.5)
    r"""The IDM exponent's range ($\delta$, ``IDMVehicle.DELTA_RANGE``)."""
    margin_rate: float = 0.5
    """Growth [m/s] of the margin added along the route on each side (beyond the spread's
    ``margin_along`` at n = 0): what the unobserved check phase and the simulation step add."""
    margin_turn: float = 0.75
    """Added across the lane [m] on each side where the route curves: in a junction's turns a slow
    vehicle's saturated steering leaves the centreline by up to about a metre (seeds 0-6: with the
    lane's 0.5 m alone, most misses in the junction were across it)."""
    upper_yields: bool = False
    """Whether the fast run obeys the yielding rule (as the mean does) instead of never yielding."""
    ego_brakes: bool = True
    """Whether the ego brakes fully in the slow run (else it follows the slow IDM)."""
    ego_leads: bool = True
    """Whether the ego brakes fully in the fast run too (else it follows the fast IDM): a road user
    behind the ego on its lane is then bounded behind an ego that stops, so that no box of it
    reaches through the ego, whatever the ego plans (when the ego drives on, that road user may
    pass its box, but behind the ego)."""

    def __post_init__(self) -> None:
        low, high = (float(x) for x in self.delta)
        if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
            raise ValueError(f"IntervalModel.delta must be finite with 0 < low <= high, got {self.delta!r}")
        for name in ("margin_rate", "margin_turn"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"IntervalModel.{name} must be a finite number >= 0, got {value!r}")
        for name in ("upper_yields", "ego_brakes", "ego_leads"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"IntervalModel.{name} must be a bool, got {getattr(self, name)!r}")


def lane_only(model: SpeedModel) -> SpeedModel:
    """``model`` with highway-env's leader search on the road user's own lane only (the fast run's)."""
    if not model.model.connected_lanes:
        return model
    return SpeedModel(model.network, model.model, LaneTable(model.network, connected=False))


def interval_bounds(
    model: SpeedModel,
    agents: Agents,
    steps: int,
    dt: float,
    intervals: IntervalModel,
    mean: tuple[np.ndarray, np.ndarray],
    ego: np.ndarray | None = None,
    lane_model: SpeedModel | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(s_lo, s_hi, v_lo, v_hi)``, each ``(A, steps+1)`` [m, m/s]: each agent's arc length and
    speed bounds from the slow and fast runs and the ``mean`` ``(s, v)``, widened by the margin
    (before the clip to the full range, which :func:`~risk_env.highway.lanes.beliefs.mode_beliefs`
    applies). ``ego``: ``(A,)`` bool, the agents that stand for the ego. ``lane_model``: ``model``
    with the leader search on the own lane only (:func:`lane_only`, built once by the caller)."""
    count = len(agents.vehicle)
    ego = np.zeros(count, dtype=bool) if ego is None else np.asarray(ego, dtype=bool)
    low, high = (float(x) for x in intervals.delta)
    fast_s, fast_v = (lane_only(model) if lane_model is None else lane_model).run(
        agents,
        steps,
        dt,
        delta=np.full(count, high),
        target=np.full(count, np.inf),
        yielding=intervals.upper_yields,
        partners=np.flatnonzero(agents.representative),
        braking=ego if intervals.ego_leads else np.zeros(count, dtype=bool),
    )
    slow_s, slow_v = model.run(
        agents,
        steps,
        dt,
        delta=np.full(count, low),
        target=np.maximum(agents.v, 0.0),
        yielding=model.model.yielding,
        partners=np.arange(count),
        braking=ego if intervals.ego_brakes else np.zeros(count, dtype=bool),
    )
    s, v = mean
    margin = intervals.margin_rate * np.arange(steps + 1) * dt
    s_lo = np.minimum(np.minimum(slow_s, fast_s), s) - margin
    s_hi = np.maximum(np.maximum(slow_s, fast_s), s) + margin
    v_lo = np.minimum(np.minimum(slow_v, fast_v), v)
    v_hi = np.maximum(np.maximum(slow_v, fast_v), v)
    return s_lo, s_hi, v_lo, v_hi
