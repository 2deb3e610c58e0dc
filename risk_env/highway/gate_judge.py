r"""How the junction gate judges a vehicle's prediction (:class:`~risk_env.highway.gate.JunctionGate`'s
``judge`` and ``tolerance``).

- ``"boxes"`` (the default): every mode of weight at least the gate's threshold occupies a point of
  the ego's path while its truncation box is within the clearance of it (the worst case over the
  mode).
- ``"footprint"``: each mode occupies the points its mean car covers: a rectangle of highway-env's
  car (:data:`CAR_HALF_LENGTH` by :data:`CAR_HALF_WIDTH`, turned by the mode's mean heading) about
  its mean, so that a mode stands for where the vehicle is most likely, not for all it could do.
- ``"near"``: its truncation boxes over the first :data:`NEAR_STEPS` steps (the MPCs' horizon of
  3 s, within which their own rows keep the ego off the same boxes), its mean car after: the boxes
  of the far future, which grow from the slowest to the fastest run, judge a gap the ego will have
  left before they are likely.
- ``"tracks"``: a lane mode is as many tracks as its stretch has samples, track $k$ at the same
  fraction $q_k$ of the stretch at every step (from the slow run's end to the fast run's: one
  vehicle's speed profile), equally likely, over the whole prediction; the mode conflicts with the
  share of its tracks that conflict, so that a gate with a ``tolerance`` accepts the chance of a
  conflict summed over the modes' conflicting tracks (with none, any conflicting track closes it).
  A mode without a stretch is judged as ``"near"`` judges it, wholly.
- ``"stretch"``: as ``"near"``, but over those first steps a lane mode is judged by the stretch of
  its route its box holds (:class:`~risk_env.highway.lanes.beliefs.Stretch`: the centreline from
  the slowest run to the fastest, and what the box adds across), not by the box: a box that holds
  a stretch of a turn is a rectangle about its arc, which covers the lanes inside and outside the
  turn (in diagnostic runs, seeds 0-9, a third of the modes that closed the gate at steps where
  going at once came through were of lanes 4 to 9 m from the ego's path, and at a quarter of those
  steps they alone closed it). A mode without one (the paper's predictor, the gate's virtual
  object) is judged by its box up to the step before, by its mean car from that step.
- ``"rollout"``: no mode is judged; the whole scene is rolled out with the ego going now, every
  road user reacting to every other, and the gate opens when the ego comes through
  (:mod:`~risk_env.highway.lanes.rollout`; the lane+interval predictor with an ego only; the gate's
  clearance, margin, threshold and tolerance do not apply, its slack is inf when open and -inf
  when closed).

A mode conflicts when it occupies a point while the ego would be there, with the gate's margin to
spare. With ``tolerance`` 0 the gate closes when any counted mode of any vehicle conflicts; above
0, when the chance of a conflict, $1 - \prod_v (1 - \sum_{m \text{ of } v \text{ conflicting}} w_m)$
(vehicles independent), exceeds it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from risk_env import checks
from risk_env.highway.predictors import GateError
from risk_env.models.frame import to_frame
from risk_env.prediction.mixture import Mixture, Mode
from risk_env.risk.disc import signed_box_distance

GATE_CLEARANCE = 3.0
"""Distance [m] between centres the gate keeps (at most ``reach``): two 2 m wide cars side by side
touch at 2 m; the discs' 4 m would make a car leaving in the lane beside the entry a conflict."""
GATE_MARGIN = 0.5
"""Time [s] the ego must have cleared a point of the zone before another vehicle reaches it."""
GATE_THRESHOLD = 0.05
"""Weight of a vehicle's route hypothesis from which the gate reckons with it."""
SUBSTEPS = 4
"""Time samples per prediction step (positions linear in between)."""
JUDGES = ("boxes", "footprint", "near", "stretch", "tracks", "rollout")
"""The gate's ways of judging a mode (module docstring)."""
MODE_JUDGES = tuple(j for j in JUDGES if j != "rollout")
"""The judges that judge each mode (all but ``"rollout"``, which rolls the scene out): those
:attr:`GateSettings.keep_open` takes."""


@dataclass
class GateDecision:
    """One step's verdict."""

    closed: bool
    """Whether the ego must wait at the stop line (the MPC gets the virtual object)."""
    committed: bool
    """Whether the ego is past the point where it can stop before the junction."""
    slack: float = math.inf
    r"""$\min_j (t^o_j - t^e_j)$ [s] over the zone (inf: not judged or nobody comes)."""


@dataclass(frozen=True)
class GateSettings:
    """How the junction gate judges (``IntersectionAdapter(gate=GateSettings(...))``; ``gate=True``
    takes these defaults, the gate's own)."""

    clearance: float = GATE_CLEARANCE
    """Distance [m] from the ego's path within which a vehicle is in conflict (at most the discs'
    summed radii)."""
    margin: float = GATE_MARGIN
    """Time [s] the ego must have cleared a point before another vehicle reaches it."""
    threshold: float = GATE_THRESHOLD
    """Weight of a mode from which the gate reckons with it."""
    judge: str = "boxes"
    """How a mode occupies the ego's path: :data:`JUDGES`."""
    tolerance: float = 0.0
    """The chance of a conflict the gate accepts (0: none)."""
    given_ego: bool = False
    """Whether the others are predicted given that the ego goes (the lane predictor with an ego):
    by the gate, and, while it is open, by the agents' predictor too."""
    slow_approach: bool = False
    r"""Whether, while the gate is closed, the agents' reference speed is capped at $\sqrt{a d}$, from
    which half the ego's largest braking $a$ stops it at the stop line $d$ ahead (the share:
    :attr:`approach_braking`)
    (:meth:`~risk_env.highway.gate.JunctionGate.stop_speed`)."""
    hard_stop: bool = False
    r"""Whether, while the gate is closed, the *applied* speed is clipped at that $\sqrt{a d}$ too, so that
    neither a soft plan nor a fallback manoeuvre carries the ego past the stop line
    (:meth:`~risk_env.highway.gate.JunctionGate.allowed_speed`)."""
    approach_braking: float = 0.5
    r"""The share $b$ of the ego's largest braking $a$ that the slow approach and the hard stop brake with:
    their speed is $\sqrt{2 b a d}$ (0.5: $\sqrt{a d}$; 1: the latest full stop), in (0, 1]."""
    follow: bool = False
    """Whether the agents' predictor widens the boxes of road users ahead on the ego's route across
    its corridor, so that the ego follows them and never passes beside
    (:func:`~risk_env.highway.lanes.follow.follow_leaders`)."""
    keep_open: str | None = None
    """The judge (one of :data:`MODE_JUDGES`) by which a gate that opened closes again
    before the ego commits (None: its own ``judge``): a gap once taken is given up only for a
    conflict that judge sees, so that a gate of boxes does not close for what is merely possible
    while the ego drives to its line."""
    passage: bool = False
    """Whether the ego drives a passage the rollout verified (the lane+interval predictor with an
    ego): while the gate is open, from the gate's range until the ego's rear leaves the junction,
    each step rolls the scene out with the ego going on (:func:`~risk_env.highway.lanes.rollout.roll_out`);
    where it comes through in every run, the agents plan without the other road users, at no more
    than the runs' lowest speed one step on (:attr:`~risk_env.highway.gate.JunctionGate.verified_speed`),
    and else keep off every box as without it."""
    leader_cap: bool = False
    r"""Whether the agents' reference speed and the applied speed are capped at
    $\sqrt{2 b a (g + v_l^2 / (2 a_l))}$, from which the approach braking $b a$
    (:attr:`approach_braking`) stops the ego behind the nearest road user ahead on its route if
    that one brakes fully ($a_l$) from its speed along the route $v_l \ge 0$ ($g$ [m]: the gap
    between their bodies, less :data:`~risk_env.highway.lanes.follow.LEADER_MARGIN`): the stop
    line's cap (:attr:`slow_approach`, :attr:`hard_stop`) for the car ahead. The MPC's horizon
    has no terminal row, so without it the ego comes on toward a queue at its reference speed
    until it can no longer stop (:func:`~risk_env.highway.lanes.follow.leader_gap`)."""


def check_gate(gate: Any) -> GateSettings | None:
    """``gate`` as the gate's settings (``True``: the defaults), or None (``False``: off); a
    :class:`GateError` naming ``gate`` for anything else."""
    if isinstance(gate, GateSettings):
        return gate
    if not isinstance(gate, (bool, np.bool_)):
        raise GateError(
            f"gate must be True, False (the junction gate on or off) or a GateSettings, got"
            f" {checks.describe(gate)}"
        )
    return GateSettings() if gate else None


NEAR_STEPS = 6
"""Prediction steps the ``"near"`` judge judges by the boxes (then by the mean car)."""
CAR_HALF_LENGTH = 2.5
"""Half of highway-env's ``Vehicle.LENGTH`` [m]."""
CAR_HALF_WIDTH = 1.0
"""Half of highway-env's ``Vehicle.WIDTH`` [m]."""


def judged(mode: Mode, judge: str) -> Mixture:
    """``mode`` alone, weight 1, as ``judge`` sees it: its truncation boxes, its mean car, or both in
    turn (``"stretch"``: as ``"near"``, whose boxes :func:`occupancy` replaces by the stretch)."""
    mode = dataclasses.replace(mode, weight=1.0, share=1.0)
    if judge in ("footprint", "near", "stretch", "tracks"):
        b = mode.beliefs
        far = np.ones(len(b.half_x), dtype=bool)
        if judge in ("near", "tracks"):
            far[: NEAR_STEPS + 1] = False
        elif judge == "stretch":  # the stretch up to NEAR_STEPS (:func:`occupancy`); from there the car,
            far[:NEAR_STEPS] = False  # so that no box leaks into the time between that step and the next
        car = dataclasses.replace(
            b,
            half_x=np.where(far, CAR_HALF_LENGTH, b.half_x),
            half_y=np.where(far, CAR_HALF_WIDTH, b.half_y),
            frame=np.where(far, np.asarray(b.theta, dtype=float), b.frame),
        )
        mode = dataclasses.replace(mode, beliefs=car)
    return Mixture((mode,))


def conflict_chance(masses: list[float]) -> float:
    r"""$1 - \prod_v (1 - m_v)$ of the vehicles' conflicting masses ``masses`` (each clipped to [0, 1])."""
    safe = math.prod(1.0 - min(max(m, 0.0), 1.0) for m in masses)
    return 1.0 - safe


def travel_time(distance: np.ndarray, speed: float, accel: float, cap: float) -> np.ndarray:
    """Time [s] to cover ``distance`` [m] (``(J,)``, <= 0: 0) from ``speed`` [m/s] accelerating at
    ``accel`` [m/s^2] up to ``cap`` [m/s]."""
    d = np.maximum(np.asarray(distance, dtype=float), 0.0)
    v0 = min(max(float(speed), 0.0), cap)
    d_acc = (cap**2 - v0**2) / (2.0 * accel)
    accelerating = (np.sqrt(v0**2 + 2.0 * accel * np.minimum(d, d_acc)) - v0) / accel
    return np.where(d <= d_acc, accelerating, (cap - v0) / accel + (d - d_acc) / cap)


def occupancy(
    mixture: Mixture, points: np.ndarray, reach: float, dt: float, threshold: float, stretch_steps: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """``(first, last)``, each ``(J,)``: the first and the last time [s] any mode of ``mixture`` of
    weight at least ``threshold`` has its truncation box within ``reach`` [m] of each of ``points
    (J, 2)`` (never: ``inf`` and ``-inf``; still within at the prediction's end: ``last`` inf); over
    the first ``stretch_steps`` steps a mode that knows its :class:`~risk_env.highway.lanes.beliefs.Stretch`
    is judged by that instead of its box."""
    first, last = np.full(len(points), math.inf), np.full(len(points), -math.inf)
    for mode in mixture.above(threshold):
        b = mode.beliefs.as_array()  # (N+1, 12)
        n = len(b)
        tau = np.linspace(0.0, (n - 1) * dt, (n - 1) * SUBSTEPS + 1)
        grid = np.arange(n) * dt
        x, y = np.interp(tau, grid, b[:, 0]), np.interp(tau, grid, b[:, 1])
        hx, hy = np.interp(tau, grid, b[:, 7]), np.interp(tau, grid, b[:, 8])
        frame = np.interp(tau, grid, np.unwrap(b[:, 11]))
        dx, dy = to_frame(points[None, :, 0] - x[:, None], points[None, :, 1] - y[:, None], frame[:, None])
        near = signed_box_distance(dx, dy, hx[:, None], hy[:, None]) < reach  # (T, J)
        stretch = getattr(mode, "stretch", None)
        if stretch_steps and stretch is not None:
            on = stretch_distance(stretch, points, tau, dt) < reach
            near = np.where((tau <= stretch_steps * dt + 1e-9)[:, None], on, near)
        mode_first, mode_last = first_last(near, tau)
        first, last = np.minimum(first, mode_first), np.maximum(last, mode_last)
    return first, last


def first_last(near: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(first, last)``: over the time axis (the first) of ``near (T, ...)``, the first and the last
    time of ``tau (T,)`` [s] that it holds (never: ``inf`` and ``-inf``; at the end: ``last`` inf)."""
    seen = near.any(axis=0)
    first = np.where(seen, tau[np.argmax(near, axis=0)], math.inf)
    last = np.where(near[-1], math.inf, tau[len(tau) - 1 - np.argmax(near[::-1], axis=0)])
    return first, np.where(seen, last, -math.inf)


def along_time(samples: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
    """``(T, K, 2)``: the positions ``samples (N+1, K, 2)`` (steps of ``dt`` [s]) at the times ``tau
    (T,)`` [s], linear in between steps."""
    n = len(samples)
    pos = np.clip(tau / dt, 0.0, n - 1)
    low = np.minimum(np.floor(pos).astype(int), max(n - 2, 0))
    frac = np.clip(pos - low, 0.0, 1.0)[:, None, None]
    return samples[low] * (1.0 - frac) + samples[np.minimum(low + 1, n - 1)] * frac


def stretch_gaps(stretch: Any, points: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
    """``(T, J, K)``: the distance [m] from each of ``points (J, 2)`` to each sample of ``stretch``
    at the times ``tau (T,)`` [s] (steps of ``dt``, linear in between), less how far across the
    road user may stray."""
    samples = np.asarray(stretch.points, dtype=float)  # (N+1, K, 2)
    at = along_time(samples, tau, dt)  # (T, K, 2)
    across = np.interp(tau, np.arange(len(samples)) * dt, np.asarray(stretch.across, dtype=float))
    return np.linalg.norm(points[None, :, None, :] - at[:, None, :, :], axis=-1) - across[:, None, None]


def stretch_distance(stretch: Any, points: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
    """``(T, J)``: the least distance [m] from each of ``points (J, 2)`` to where a road user's
    centre may be at each time ``tau (T,)`` [s] (steps of ``dt``): :func:`stretch_gaps` over the
    stretch's samples, less half their spacing."""
    steps_along = np.linalg.norm(np.diff(np.asarray(stretch.points, dtype=float), axis=1), axis=-1)
    spacing = float(steps_along.max()) if steps_along.size else 0.0
    return stretch_gaps(stretch, points, tau, dt).min(axis=-1) - spacing / 2.0


def track_apart(
    stretch: Any, points: np.ndarray, reach: float, dt: float, ego_in: np.ndarray, ego_out: np.ndarray
) -> np.ndarray:
    r"""``(K,)``: for each track of ``stretch`` (module docstring, ``"tracks"``), the least over the
    ``points (J, 2)`` of $\max(t^o_{in,j} - t^e_{out,j}, t^e_{in,j} - t^o_{out,j})$ [s], the time by
    which it and the ego (at point $j$ from ``ego_in`` to ``ego_out``, each ``(J,)``) keep apart
    (below the gate's margin: a conflict); ``reach`` [m] is the gate's clearance."""
    n = len(stretch.points)
    tau = np.linspace(0.0, (n - 1) * dt, max((n - 1) * SUBSTEPS, 0) + 1)
    first, last = first_last(stretch_gaps(stretch, points, tau, dt) < reach, tau)  # (J, K) each
    apart = np.maximum(first - ego_out[:, None], ego_in[:, None] - last)  # (J, K)
    return apart.min(axis=0)


def mode_conflict(
    mode: Mode,
    judge: str,
    points: np.ndarray,
    reach: float,
    dt: float,
    ego_in: np.ndarray,
    ego_out: np.ndarray,
    margin: float,
) -> tuple[float, float]:
    """``(apart, share)`` of ``mode`` as ``judge`` sees it, for the ego at ``points (J, 2)`` from
    ``ego_in`` to ``ego_out`` [s] (each ``(J,)``): the least time [s] by which they keep apart (it
    comes after the ego has cleared a point, or has left before the ego comes), and the share of the
    mode that conflicts (keeps apart by less than ``margin`` [s]: 0 or 1, or, for ``"tracks"``, the
    share of its tracks); ``reach`` [m] is the gate's clearance, ``dt`` [s] the prediction step."""
    stretch = getattr(mode, "stretch", None)
    if judge == "tracks" and stretch is not None:
        apart_k = track_apart(stretch, points, reach, dt, ego_in, ego_out)
        return float(apart_k.min()), float(np.mean(apart_k < margin))
    stretch_steps = NEAR_STEPS if judge == "stretch" else 0
    first, last = occupancy(judged(mode, judge), points, reach, dt, 0.0, stretch_steps)
    apart = float(np.min(np.maximum(first - ego_out, ego_in - last)))
    return apart, float(apart < margin)
