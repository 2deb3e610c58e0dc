r"""The lane predictor's beliefs: truncated Gaussians in the lane's frame around each mode's mean.

A mode's belief at step $n$ (:func:`mode_beliefs`) lies in a frame of its route's heading
(:attr:`Belief.frame <risk_env.prediction.belief.Belief.frame>`): the heading at the mean, or at
the middle of the stretch of the route the road user can reach (on a circular lane, the direction
of that stretch's chord), whichever gives the smaller box:

- **Along the lane** the truncation box reaches from full braking (``a_max``, down to a stop, or
  at the current speed if the road user rolls backwards) to full acceleration up to the speed limit
  (:func:`~risk_env.highway.lanes.speed.reach`), and at least to each of the mode's routes' own
  means, plus ``margin_along``. The box is the smallest one around the mean (in that frame) that
  holds the centreline between those two ends, so that on a curve it widens across the lane to
  hold the arc; across, it adds ``margin_across``.
- The standard deviation along the lane at time $t$ is
  $\sqrt{\sigma_{along,0}^2 + (\sigma_v t)^2 + (\sigma_a t^2 / 2)^2}$ (at most the box's half
  length), across it $\sigma_{across}$ (at most the box's half width and half the lane's width); the
  speed's is $\sigma_v + \sigma_a t$ ($\sigma_{along,0}$, $\sigma_v$, $\sigma_a$, $\sigma_{across}$:
  :class:`Spread`'s ``sigma_along0``, ``sigma_speed``, ``sigma_accel``, ``sigma_across``), truncated
  to the speeds of full braking and full acceleration (and every route's mean speed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from risk_env.highway.lanes.routes import Route
from risk_env.highway.lanes.speed import reach
from risk_env.prediction.belief import Belief

CURVED = 1e-3
"""Curvature [1/m] above which a route counts as curving (``margin_turn``)."""
BOX_SPACING = 1.0
"""Largest spacing [m] of the centreline points that a truncation box must hold."""


@dataclass(frozen=True)
class Spread:
    """The numbers of the beliefs' spread (see the module docstring)."""

    margin_along: float = 0.5
    """Added to the truncation box along the lane, on each side [m]."""
    margin_across: float = 0.5
    """Added to the truncation box across the lane, on each side [m]."""
    sigma_along0: float = 0.2
    """Standard deviation along the lane at $n = 0$ [m]."""
    sigma_speed: float = 0.5
    r"""Standard deviation of the speed [m/s] (its growth along the lane: $\sigma_v t$)."""
    sigma_accel: float = 1.5
    r"""Standard deviation of the acceleration [m/s²] (along: $\sigma_a t^2 / 2$)."""
    sigma_across: float = 0.2
    """Standard deviation across the lane [m]."""

    def __post_init__(self) -> None:
        for name in (
            "margin_along",
            "margin_across",
            "sigma_along0",
            "sigma_speed",
            "sigma_accel",
            "sigma_across",
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"Spread.{name} must be a finite number >= 0, got {value!r}")


@dataclass(frozen=True)
class Stretch:
    """Where a mode's road user may be along its route: the centreline (with the lateral offset) from
    the box's rear end to its front end, sampled every :data:`BOX_SPACING` metres or closer, and how
    far across it may stray (what the box adds across): the shape the box holds, for a judge that
    needs no box (:mod:`~risk_env.highway.gate_judge`'s ``"stretch"``)."""

    points: np.ndarray
    """``(N+1, count, 2)``: world positions [m] along the stretch at each step."""
    across: np.ndarray
    """``(N+1,)``: how far [m] the centre may lie off those points across the lane."""


def mode_beliefs(
    spread: Spread,
    route: Route,
    s: np.ndarray,
    v: np.ndarray,
    share: np.ndarray,
    start: float,
    offset: float,
    speed: float,
    dt: float,
    a_max: float,
    lateral_time: float,
    piece: tuple[int, int] = (0, 1),
    bounds: tuple[np.ndarray, ...] | None = None,
    margin_turn: float = 0.0,
    centred: bool = False,
    fitted: bool = False,
    drift: tuple[float, float] | None = None,
) -> tuple[Belief, Stretch]:
    """The beliefs (fields ``(N+1,)``) of one mode, each in its own frame, and the stretch they hold.

    ``route``: the geometry (the mode's most likely route); ``s``, ``v``: ``(R, N+1)`` arc lengths
    [m] and speeds [m/s] of the mode's routes (same arc length along their shared lanes), ``share``:
    their weights within the mode ``(R,)``; ``start``, ``offset``: the road user's arc length and
    lateral offset [m] now, ``speed`` its speed [m/s]; ``dt`` [s]; ``a_max`` [m/s^2] of full
    braking and acceleration; ``lateral_time`` [s] with which the offset decays. ``piece`` ``(j, P)``:
    the j-th of P equal bands of the reachable stretch along the route (from full braking to full
    acceleration), its mean at the band's middle (P = 1: the whole stretch around the mean).
    ``bounds``: ``(s_lo, s_hi, v_lo, v_hi)`` ``(R, N+1)`` of the mode's routes (the interval
    prediction, :func:`~risk_env.highway.lanes.interval.interval_bounds`) instead of full braking to
    full acceleration, clipped to that full range; ``margin_turn`` [m] is added across where the
    route curves at the mean; ``centred``: the mean along the route at the middle of ``bounds``;
    ``fitted``: each box the tightest in its frame that holds the stretch, the mean at its centre
    (else symmetric about the mean); ``drift``: ``(rate, cap)``, each box widened across by ``rate``
    [m/m] per metre the road user may have reversed by then (its lowest speed's), up to ``cap`` [m]
    (:attr:`~risk_env.highway.lanes.interval.IntervalModel.reversing`), or None."""
    steps = s.shape[1] - 1
    t = np.arange(steps + 1) * dt
    s_mean, v_mean = share @ s, share @ v
    limit = float(route.speed_limit(start))
    limit = max(speed, 0.0) + a_max * t[-1] if not math.isfinite(limit) else limit
    low, high = reach(speed, limit, steps, dt, a_max)
    s_lo = np.minimum(s.min(axis=0), start + low) - spread.margin_along
    s_hi = np.maximum(s.max(axis=0), start + high) + spread.margin_along
    v_lo = np.minimum(v.min(axis=0), np.maximum(speed - a_max * t, min(speed, 0.0)))
    v_hi = np.maximum(v.max(axis=0), np.minimum(speed + a_max * t, max(limit, speed)))
    if bounds is not None:  # within the full range, so an interval box lies inside the full one
        lo, hi, slow, fast = (np.asarray(b, dtype=float) for b in bounds)
        s_lo, s_hi = (
            np.clip(lo.min(axis=0) - spread.margin_along, s_lo, s_hi),
            np.clip(hi.max(axis=0) + spread.margin_along, s_lo, s_hi),
        )
        v_lo, v_hi = np.clip(slow.min(axis=0), v_lo, v_hi), np.clip(fast.max(axis=0), v_lo, v_hi)
        if centred:  # the box is symmetric about the mean: centred on the interval, it is no longer
            s_mean = (s_lo + s_hi) / 2  # than the interval (about the IDM's mean: up to twice)
    j, pieces = piece
    if pieces > 1:
        band = (s_hi - s_lo) / pieces
        s_lo, s_hi = s_lo + j * band, s_lo + (j + 1) * band
        s_mean = (s_lo + s_hi) / 2
    lateral = offset * np.exp(-t / lateral_time)
    mean = route.position(s_mean, lateral)
    count = max(int(math.ceil(float((s_hi - s_lo).max()) / BOX_SPACING)), 1) + 1
    grid = s_lo[:, None] + (s_hi - s_lo)[:, None] * np.linspace(0.0, 1.0, count)[None, :]
    on_route = route.position(grid, np.broadcast_to(lateral[:, None], grid.shape))
    points = on_route - mean[:, None, :]
    candidates = np.stack([route.heading(s_mean), route.heading((s_lo + s_hi) / 2)])  # (2, N+1)
    c, si = np.cos(candidates)[..., None], np.sin(candidates)[..., None]
    along = c * points[None, ..., 0] + si * points[None, ..., 1]  # (2, N+1, count) in each frame
    side = c * points[None, ..., 1] - si * points[None, ..., 0]
    if fitted:  # about the stretch's extent: the centre's offset from the mean in each frame
        mid_x, mid_y = (along.max(-1) + along.min(-1)) / 2, (side.max(-1) + side.min(-1)) / 2
    else:
        mid_x = mid_y = np.zeros(along.shape[:2])
    extra = margin_turn * (np.abs(route.curvature(s_mean)) > CURVED)  # (N+1,): added across
    if drift is not None:
        extra = extra + reverse_drift(v_lo, dt, *drift)
    half_x = np.abs(along - mid_x[..., None]).max(axis=-1)
    half_y = np.abs(side - mid_y[..., None]).max(axis=-1) + spread.margin_across + extra[None, :]
    best = np.argmin(half_x * half_y, axis=0)  # (N+1,): the smaller box
    columns = np.arange(steps + 1)
    frame, half_x, half_y = candidates[best, columns], half_x[best, columns], half_y[best, columns]
    mid_x, mid_y = mid_x[best, columns], mid_y[best, columns]
    mean = mean + np.stack(
        [np.cos(frame) * mid_x - np.sin(frame) * mid_y, np.sin(frame) * mid_x + np.cos(frame) * mid_y], axis=1
    )
    width = np.array([float(route.objects[int(k)].width_at(0.0)) for k in route.lane_of(s_mean)])
    growth = np.sqrt(
        spread.sigma_along0**2 + (spread.sigma_speed * t) ** 2 + (spread.sigma_accel * t**2 / 2) ** 2
    )
    sigma_x = np.minimum(growth, half_x)
    sigma_y = np.minimum(np.minimum(spread.sigma_across, half_y), width / 2)
    sigma_v = spread.sigma_speed + spread.sigma_accel * t
    heading = route.heading(s_mean)
    belief = lane_belief(
        mean[:, 0], mean[:, 1], heading, v_mean, sigma_x, sigma_y, sigma_v, half_x, half_y, v_lo, v_hi, frame
    )
    return belief, Stretch(on_route, spread.margin_across + extra)


def reverse_drift(v_lo: np.ndarray, dt: float, rate: float, cap: float) -> np.ndarray:
    """``(N+1,)``: how far [m] a road user whose lowest speeds are ``v_lo (N+1,)`` [m/s] may have
    drifted sideways by each step, reversing: ``rate`` [m/m] per metre reversed (the lowest speed
    of each step's two ends), up to ``cap`` [m]."""
    back = np.maximum(-np.minimum(v_lo[:-1], v_lo[1:]), 0.0) * dt
    return np.minimum(rate * np.concatenate([[0.0], np.cumsum(back)]), cap)


def lane_belief(
    x: Any,
    y: Any,
    heading: Any,
    speed: Any,
    sigma_along: Any,
    sigma_across: Any,
    sigma_v: Any,
    half_along: Any,
    half_across: Any,
    v_lo: Any,
    v_hi: Any,
    frame: Any,
) -> Belief:
    """A :class:`~risk_env.prediction.belief.Belief` with mean heading ``heading`` [rad] in the
    frame turned by ``frame`` [rad] from the world's axes: ``sigma_along``/``half_along`` along
    that frame's first axis (the lane), ``sigma_across``/``half_across`` across it."""
    spread = (sigma_along, sigma_across, sigma_v, half_along, half_across, v_lo, v_hi)
    return Belief(x, y, heading, speed, *spread, frame=frame)
