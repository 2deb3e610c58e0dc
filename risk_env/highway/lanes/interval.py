r"""Interval prediction over highway-env's IDM parameters: bounds on a route hypothesis's arc length
and speed at n = 0..N, for the lane predictor's ``longitudinal="interval"`` (``"lane+interval"``).

highway-env's traffic (``IDMVehicle`` as ``intersection-v2`` sets it) draws one IDM parameter per
vehicle, the exponent $\delta$ uniformly in ``DELTA_RANGE`` = [3.5, 4.5]
(``randomize_behavior``); its desired speed is its speed at spawn (``target_speed``), set to the
lane's limit when it stops yielding and to 0 while it yields; $A$, $B$, $d_0$, $\tau$ and the clip
$a_{max}$ are the class's own numbers. Following Leurent's interval predictor
(``highway_env.vehicle.uncertainty.prediction.IntervalVehicle``), which propagates the state
interval through the IDM with its parameters in a box, each road user's routes are moved twice
(four times when split, below), every road user of the scene together (the speed model of
:mod:`~risk_env.highway.lanes.speed`):

- **fast** (the upper bound): $\delta$ at the top of its range and the desired speed at the lane's
  limit (while $v \le v_0$ the IDM's free term grows with both), behind the leaders' fast
  futures on the road user's own lane only: highway-env's search on connected lanes also takes an
  oncoming vehicle on the approach beside an exit (or the exit beside an approach) for a leader,
  at its coordinate on the follower's lane, and a vehicle spawned at the approach's start then
  replaces it by one far away, which no prediction sees coming, so the upper bound does without
  those leaders; nobody yields (:attr:`IntervalModel.upper_yields` False), unless asked to apply
  the regulation's rule as the mean does; the ego (when the predictor is given one) brakes fully
  (:attr:`IntervalModel.ego_leads`), so that no box of a road user behind it reaches through it,
  and with :attr:`IntervalModel.ego_ahead` it is found on every lane of the connected search;
- **slow** (the lower bound): $\delta$ at the bottom of its range and the desired speed at the
  measured speed (a vehicle that does not yield never wants less than it drives), behind the
  nearest of every route hypothesis of every other road user, and yielding to any of them under
  the regulation's rule; the ego (when the predictor is given one) brakes fully.
- **Held or free** (:attr:`IntervalModel.split_yield`, :class:`IntervalBounds`): one box over
  both runs holds a road user that stops at its line (it yields, in the slow run) and one that
  drives through (the fast run), so that once its box reaches a point it stays there to the end
  of the prediction. A road user the slow run holds (it yields, or waits behind one that does) is
  therefore split in two: *held* (the slow run, and a fast run that yields to everyone as the slow
  one does) and *free* (the fast run, and a slow run in which nobody yields), weighted by the
  rule's chance: the weight of the routes of the road users it yields to that it yields to.
- **Given the ego** (``ego_motion``, the junction gate's question "what if I go now"): the ego
  drives on in every run, accelerating up to its speed, instead of braking, never yielding (as
  highway-env leaves its controlled vehicle), so that traffic that would follow it brakes
  behind it.

The IDM's acceleration grows with the leader's position and speed and falls with the follower's
own position, so a follower behind its leader's upper (lower) future tends to stay at or below
(above) its own upper (lower) one. These are not guaranteed bounds: the IDM is not monotone in the
follower's own speed, the yielding rule is a discrete decision on constant-speed futures, and
vehicles spawn; the prediction benchmark measures how often they hold. The bounds on each step are
the runs' and the mean's extremes widened by ``margin_rate`` times the time (the regulation's check
phase, 0.5 s, is not observed, nor is the simulation's 1/16 s step), clipped to the lane
predictor's full range (full braking to full acceleration), so that along the lane an interval box
lies within the full-range one; across a curving route the box widens by ``margin_turn``. A box is
symmetric about its mode's mean, so the mean is put at the interval's middle
(:attr:`IntervalModel.centred`): about the IDM's mean run, the box would reach as far behind the
mean as the fast run reaches ahead of it.
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
    split_yield: bool = False
    """Split each road user's box into a *held* mode (it yields, or waits behind one that does) and a
    *free* one (it drives on), weighted by the yielding rule's chance (:class:`IntervalBounds`),
    instead of one box that holds both."""
    centred: bool = False
    """Whether a mode's mean along the route lies at the middle of its interval (its box, which is
    symmetric about the mean, then no longer than the interval) instead of at the IDM's mean run."""
    fitted: bool = False
    """Whether each box is the tightest box in its frame that holds the reachable stretch, the
    mode's mean moved to its centre, instead of a box symmetric about the mean: on a curve the arc
    bows to the inside of its chord, and a box symmetric about the arc's middle reaches as far
    to the outside, where it covered the concentric lane 4 m away (the ego's left turn beside a
    right turn: in diagnostic runs a third of the modes that closed the junction gate at steps where
    going at once came through were of such lanes, 4 to 9 m from the ego's path)."""
    yield_to_ego: bool = False
    """Whether every box ends where a fast run with the ego standing (braking fully, even in a
    prediction given that it goes) stops the road user: behind the ego if it follows it, before
    it if it yields to it (highway-env's rule: lower priority, or the same and behind; nobody
    else is yielded to). A road user held so passes that point only into room the ego has left
    (the ego never reverses), so no box runs through a standing ego, and standing stays a plan."""
    ego_leads: bool = True
    """Whether the ego brakes fully in the fast run too (else it follows the fast IDM): a road user
    behind the ego on its lane is then bounded behind an ego that stops, so that no box of it
    reaches through the ego, whatever the ego plans (when the ego drives on, that road user may
    pass its box, but behind the ego)."""
    reversing: bool = False
    """Whether a road user whose lowest speeds go below zero (it rolls back now, or a run has it
    reverse: highway-env's IDM brakes through a stop when its leader is too close) is widened
    across, on each side, by ``drift_rate`` per metre they take it back, up to ``drift_cap``:
    highway-env's lane keeping steers the wrong way in reverse, so the car leaves its lane's
    centreline and turns (the prediction benchmark's phase ``reversing`` scores such cars)."""
    drift_rate: float = 1.0
    """Sideways drift [m] per metre reversed (``reversing``)."""
    drift_cap: float = 1.5
    """Largest sideways drift [m] of a reversing road user (``reversing``)."""
    ego_ahead: bool = False
    """Whether the runs whose leader search keeps to the road user's own lane (the fast ones) still
    take the ego for a leader on every lane highway-env's connected search covers (the lanes the
    graph joins before and after it, within a metre of their edges): its traffic brakes for an ego
    that stands or drives in the junction ahead of its approach, which those runs drove through."""

    def __post_init__(self) -> None:
        low, high = (float(x) for x in self.delta)
        if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
            raise ValueError(f"IntervalModel.delta must be finite with 0 < low <= high, got {self.delta!r}")
        for name in ("margin_rate", "margin_turn", "drift_rate", "drift_cap"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"IntervalModel.{name} must be a finite number >= 0, got {value!r}")
        switches = (
            "upper_yields",
            "ego_brakes",
            "ego_leads",
            "split_yield",
            "centred",
            "fitted",
            "yield_to_ego",
            "ego_ahead",
            "reversing",
        )
        for name in switches:
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"IntervalModel.{name} must be a bool, got {getattr(self, name)!r}")


def lane_only(model: SpeedModel) -> SpeedModel:
    """``model`` with highway-env's leader search on the road user's own lane only (the fast run's)."""
    if not model.model.connected_lanes:
        return model
    return SpeedModel(model.network, model.model, LaneTable(model.network, connected=False), model.table)


HELD_GAP = 1.0
"""How far [m] the slow run must end behind the slow run in which nobody yields for a road user to
count as held (it yields, or waits behind one that does)."""

Bounds = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""``(s_lo, s_hi, v_lo, v_hi)``, each ``(A, N+1)`` [m, m/s]."""


@dataclass(frozen=True)
class IntervalBounds:
    """The interval prediction of every agent (:func:`interval_bounds`).

    ``union`` bounds every run (one box that holds both yielding and driving on). With
    :attr:`IntervalModel.split_yield`, ``held`` bounds the runs in which the road users follow the
    yielding rule (the slow run and a fast run that yields as it does), ``free`` those in which
    nobody yields (the fast run and a slow run without the rule), and ``chance`` ``(A,)`` is the
    probability that the agent is held: the rule's chance at its first yield in the slow run
    (:meth:`SpeedModel.run`'s ``yields``), or, for one that only waits behind a yielding road user,
    the largest such chance of the scene; 0 where the slow run is not held."""

    union: Bounds
    held: Bounds | None = None
    free: Bounds | None = None
    chance: np.ndarray | None = None

    def part(self, rows: slice | np.ndarray) -> IntervalBounds:
        """The bounds of the agents ``rows``."""

        def cut(b: Bounds | None) -> Bounds | None:
            return None if b is None else tuple(x[rows] for x in b)  # type: ignore[return-value]

        chance = None if self.chance is None else self.chance[rows]
        return IntervalBounds(cut(self.union), cut(self.held), cut(self.free), chance)  # type: ignore[arg-type]


def _envelope(runs: list[tuple[np.ndarray, np.ndarray]], margin: np.ndarray) -> Bounds:
    s = np.stack([r[0] for r in runs])
    v = np.stack([r[1] for r in runs])
    return s.min(axis=0) - margin, s.max(axis=0) + margin, v.min(axis=0), v.max(axis=0)


def interval_bounds(
    model: SpeedModel,
    agents: Agents,
    steps: int,
    dt: float,
    intervals: IntervalModel,
    mean: tuple[np.ndarray, np.ndarray],
    ego: np.ndarray | None = None,
    lane_model: SpeedModel | None = None,
    ego_motion: tuple[float, float] | None = None,
) -> IntervalBounds:
    """Each agent's arc length and speed bounds from the slow and fast runs and the ``mean``
    ``(s, v)`` ``(A, steps+1)``, widened by the margin (before the clip to the full range, which
    :func:`~risk_env.highway.lanes.beliefs.mode_beliefs` applies), split into held and free with
    :attr:`IntervalModel.split_yield`. ``ego``: ``(A,)`` bool, the agents that stand for the ego.
    ``lane_model``: ``model`` with the leader search on the own lane only (:func:`lane_only`,
    built once by the caller). ``ego_motion`` ``(a, v)``: the ego drives on, accelerating at a
    [m/s²] up to v [m/s], in every run (a prediction given that the ego goes), instead of braking."""
    count = len(agents.vehicle)
    ego = np.zeros(count, dtype=bool) if ego is None else np.asarray(ego, dtype=bool)
    low, high = (float(x) for x in intervals.delta)
    lane_model = lane_only(model) if lane_model is None else lane_model
    everyone = np.arange(count)
    none = np.zeros(count, dtype=bool)
    going = ego_motion is not None
    fast_ego = ego if (intervals.ego_leads or going) else none
    ego_rule = {"script": ego_motion, "exempt": ego if going else None}
    fast_options = {
        "delta": np.full(count, high),
        "target": np.full(count, np.inf),
        "scripted": fast_ego,
        "wide": ego if intervals.ego_ahead else None,
    }
    fast = lane_model.run(
        agents,
        steps,
        dt,
        yielding=intervals.upper_yields,
        partners=np.flatnonzero(agents.representative),
        **fast_options,
        **ego_rule,
    )
    slow_options = {
        "delta": np.full(count, low),
        "target": np.maximum(agents.v, 0.0),
        "partners": everyone,
        "scripted": ego if (intervals.ego_brakes or going) else none,
        **ego_rule,
    }
    first_yield = np.zeros(count)
    slow = model.run(agents, steps, dt, yielding=model.model.yielding, yields=first_yield, **slow_options)
    margin = intervals.margin_rate * np.arange(steps + 1) * dt
    cap = None
    if intervals.yield_to_ego and ego.any():  # the ego stands: who follows it or yields to it stops
        options = {**fast_options, "scripted": ego, "script": None, "exempt": ego, "yield_to": ego}
        standing = lane_model.run(
            agents, steps, dt, yielding=True, partners=np.flatnonzero(agents.representative), **options
        )
        cap = np.where(ego[:, None], np.inf, standing[0] + margin)
    union = _capped(_envelope([slow, fast, mean], margin), cap)
    if not (intervals.split_yield and model.model.yielding):
        return IntervalBounds(union)
    free_slow = model.run(agents, steps, dt, yielding=False, **slow_options)
    held = (first_yield > 0) | (slow[0][:, -1] < free_slow[0][:, -1] - HELD_GAP)
    if not held.any():
        return IntervalBounds(union, chance=np.zeros(count))
    held_fast = lane_model.run(
        agents, steps, dt, yielding=True, partners=everyone, **fast_options, **ego_rule
    )
    waiting = held & (first_yield == 0)
    chance = np.where(first_yield > 0, first_yield, np.where(waiting, first_yield.max(), 0.0))
    held_bounds = _capped(_envelope([slow, held_fast], margin), cap)
    return IntervalBounds(union, held_bounds, _capped(_envelope([free_slow, fast], margin), cap), chance)


def _capped(bounds: Bounds, cap: np.ndarray | None) -> Bounds:
    """``bounds`` with the upper arc length at most ``cap`` ``(A, steps+1)`` (None: as they are), and
    never below the lower one."""
    if cap is None:
        return bounds
    lo, hi, v_lo, v_hi = bounds
    return lo, np.maximum(lo, np.minimum(hi, cap)), v_lo, v_hi
