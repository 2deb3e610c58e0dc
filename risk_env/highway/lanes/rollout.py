r"""The scene rolled out with the ego going now: whether the ego comes through (the junction
gate's ``"rollout"`` judge, :class:`~risk_env.highway.gate.JunctionGate`).

The lane predictor's speed model (:mod:`~risk_env.highway.lanes.speed`: highway-env's IDM and its
intersection's yielding rule, every road user together) moves every route hypothesis of the scene
with the ego on its planned route (:class:`~risk_env.highway.lanes.hypotheses.EgoPlan`), going
now at its acceleration up to its speed, never yielding, and braking for its leader as
highway-env's IDM does (what the MPC does with a car ahead in its lane); the others brake for it
and yield to it as highway-env's traffic does. Three runs span the IDM's unknown numbers: the
exponent at the bottom of the interval prediction's range with a desired speed of at least
:attr:`RolloutModel.target_floor` (none for a road user that stands: it may stay, as a wreck does),
the speed model's own numbers, and the exponent at the top with the lane's limit as desired speed.

The ego **comes through** when, in every run, its centre gets :attr:`RolloutModel.past` metres
into the last lane of its plan within :attr:`RolloutModel.horizon` (unless even a free road would
not take it there: :attr:`RolloutModel.waits`), and until then its body
(highway-env's car widened by :attr:`RolloutModel.clearance` on each side) meets no route
hypothesis of weight at least :attr:`RolloutModel.min_weight` (highway-env's rectangle test,
:func:`~risk_env.highway.lanes.routes.rectangles_intersect`, on the positions between steps), nor
a road user off the road (taking no part in the runs, it drives on at its speed and heading, as
the paper's constant predictor has it). With the interval prediction's ``reversing``, a road user
that may reverse is widened across by its drift, and one rolling back now (:data:`REVERSING`)
also moves on at its speed and heading.
Unlike the other judges, which take the ego through the junction at full acceleration whatever
is in its way, this one lets every road user react to every other: a crossing car that brakes
for an ego already in its lane, an ego that waits inside the junction for a car crossing ahead
of it (and is then not through if it waits too long).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from risk_env.highway.lanes.hypotheses import EgoPlan
from risk_env.highway.lanes.routes import interpolate, rectangles_intersect
from risk_env.highway.lanes.speed import stack_samples

REVERSING = 0.5
"""Speed [m/s] below minus which a road user counts as rolling back (:attr:`IntervalModel.reversing
<risk_env.highway.lanes.interval.IntervalModel.reversing>`): highway-env's lane keeping steers it
off its lanes, so the rollout also moves it on at its measured speed and heading."""
RUNS = ("slow", "mean", "fast")
"""The runs, in the order they are tried (module docstring)."""


@dataclass(frozen=True)
class RolloutModel:
    """The numbers of the rollout (module docstring)."""

    horizon: float = 8.0
    """How long [s] the scene is rolled out (the ego crosses from a stop in about 5)."""
    past: float = 5.0
    """How far [m] into the last lane of its plan the ego's centre must get: a car's length, so
    that its rear has left the junction."""
    clearance: float = 0.0
    """Added [m] to each side of the ego's body and each road user's."""
    min_weight: float = 0.05
    """A route hypothesis less likely than this is not a conflict (its road user still takes part)."""
    target_floor: float = 7.0
    """The slow run's lowest desired speed [m/s]: highway-env spawns its traffic at 8 m/s with a
    standard deviation of 1 and keeps that as its desired speed; a measured speed below it says
    the vehicle brakes, not that it wants to crawl."""
    samples: int = 8
    """Positions tested per step."""
    waits: bool = True
    """Whether an ego that could not reach its exit within the horizon even on a free road (from 40 m
    out at 8 m/s it cannot) is through when nothing met it: the horizon, not the traffic, keeps it
    short, and each step judges again before the ego commits. Else it must always reach its exit."""
    standing: float = 0.5
    """A road user slower than this [m/s] stays where it is in the slow run (a car waiting for a
    gap, or a wreck, which highway-env leaves where it crashed), instead of setting off for
    :attr:`target_floor`."""

    def __post_init__(self) -> None:
        for name in ("horizon", "past", "clearance", "min_weight", "target_floor", "standing"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"RolloutModel.{name} must be a finite number >= 0, got {value!r}")
        if self.horizon <= 0:
            raise ValueError(f"RolloutModel.horizon must be > 0 [s], got {self.horizon!r}")
        if self.min_weight > 1:
            raise ValueError(f"RolloutModel.min_weight must lie in [0, 1], got {self.min_weight!r}")
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) or self.samples < 1:
            raise ValueError(f"RolloutModel.samples must be an integer >= 1, got {self.samples!r}")


@dataclass(frozen=True)
class Rollout:
    """The rollout's verdict: whether the ego comes through, and if not, why."""

    through: bool
    reason: str = ""
    """Empty when through; else the first run that failed and how (the ego short of its exit, or
    the road user it met, its route and the time)."""
    speed: float = math.inf
    """When through: the ego's lowest speed [m/s] one step on, over the runs (the first input the runs'
    plans share; it brakes there only for its leader); else inf."""


def free_reach(v: float, plan: EgoPlan, horizon: float) -> float:
    """How far [m] the ego gets in ``horizon`` [s] from speed ``v`` [m/s] on a free road: at
    ``plan.accel`` up to ``plan.speed`` (from above it, at ``plan.speed``)."""
    v = min(max(v, 0.0), plan.speed)
    t = min((plan.speed - v) / plan.accel, horizon)
    return v * t + 0.5 * plan.accel * t**2 + plan.speed * (horizon - t)


def roll_out(
    predictor: Any,
    measurements: np.ndarray,
    plan: EgoPlan,
    signals: list | None = None,
    model: RolloutModel | None = None,
) -> Rollout:
    """Whether the ego of ``predictor`` (a :class:`~risk_env.highway.lanes.predictor.LanePredictor`
    with an ``ego``) comes through going now as ``plan`` says, among the road users measured as
    ``measurements (m, 5)`` with their turn ``signals`` (or None), by the module's rollout."""
    model = RolloutModel() if model is None else model
    if getattr(predictor, "ego", None) is None or not hasattr(predictor, "scene"):
        raise ValueError("the rollout needs a lane predictor with an ego (lane+interval, ego=...)")
    dt = float(predictor.dt)
    steps = max(int(math.ceil(model.horizon / dt)), 1)
    scene = predictor.scene(measurements, steps, signals=signals, ego_plan=plan)
    egos = np.flatnonzero(scene.is_ego)
    if len(egos) != 1 or scene.motion is None:
        return Rollout(False, "the ego is off the road or off its plan")
    agents, ego = scene.agents, int(egos[0])
    route = agents.routes[ego]
    if tuple(plan.lanes[-1]) in route.lanes:
        goal = float(route.offsets[route.lanes.index(tuple(plan.lanes[-1]))]) + model.past
    elif model.waits:  # the prediction's routes end where it can reach: the horizon keeps it short
        goal = math.inf
    else:
        return Rollout(False, "the ego cannot reach the last lane of its plan within the horizon")
    free = free_reach(float(agents.v[ego]), plan, steps * dt)
    count = len(agents.vehicle)
    low, high = (float(x) for x in predictor.intervals.delta)
    stays = (np.abs(agents.v) < model.standing) & ~scene.is_ego
    slow_target = np.where(stays, 0.0, np.maximum(agents.v, model.target_floor))
    options = {
        "slow": {"delta": np.full(count, low), "target": slow_target},
        "mean": {},
        "fast": {"delta": np.full(count, high), "target": np.full(count, np.inf)},
    }
    traffic = predictor.traffic
    samples = stack_samples([r.samples for r in agents.routes])
    tau = np.linspace(0.0, steps, steps * model.samples + 1)  # in steps
    low = np.minimum(np.floor(tau).astype(int), steps - 1)
    frac = (tau - low)[None, :]
    fade = np.exp(-tau * dt / traffic.lateral_time)
    others = np.flatnonzero(~scene.is_ego & (agents.weight >= model.min_weight))
    stray = [i for i, hyp in enumerate(scene.hypotheses[: scene.users]) if hyp is None]
    if predictor.intervals.reversing:  # rolling back: also on at its speed and heading, off its lanes
        stray += [i for i in range(scene.users) if scene.rows[i, 3] < -REVERSING and i not in stray]
    length, width = traffic.vehicle_length + 2 * model.clearance, traffic.vehicle_width + 2 * model.clearance
    speed = math.inf
    for run in RUNS:
        s, v = predictor.speed_model.run(
            agents,
            steps,
            dt,
            scripted=scene.is_ego,
            script=scene.motion,
            exempt=scene.is_ego,
            script_follows=True,
            **options[run],
        )
        along = s[:, low] * (1.0 - frac) + s[:, low + 1] * frac  # (A, T): linear between steps
        speed = min(speed, float(v[ego, 1]))
        arrived = np.flatnonzero(along[ego] >= goal)
        if not len(arrived) and not (model.waits and goal - s[ego, 0] > free):
            return Rollout(False, f"{run} run: the ego is {goal - s[ego, -1]:.1f} m short of its exit")
        until = tau[: arrived[0] + 1] if len(arrived) else tau
        pose = interpolate(samples, along[:, : len(until)])  # (A, T, 3)
        normal = np.stack([-np.sin(pose[..., 2]), np.cos(pose[..., 2])], axis=-1)
        points = pose[..., :2] + (agents.r[:, None] * fade[None, : len(until)])[..., None] * normal
        tracks = [
            (points[a], pose[a, :, 2], f"road user {agents.vehicle[a]} ({agents.routes[a].label()})")
            for a in others
        ]
        for user in stray:  # at its speed and heading, as the paper's constant predictor
            x, y, theta, v = scene.rows[user, :4]
            t = until * dt
            track = np.column_stack([x + v * t * math.cos(theta), y + v * t * math.sin(theta)])
            why = "off the road" if scene.hypotheses[user] is None else "rolling back"
            tracks.append((track, np.full(len(t), theta), f"road user {user} ({why})"))
        drift = np.zeros(len(tracks))  # both bodies widened by half of it: the pair's gap by all of it
        iv = predictor.intervals
        if iv.reversing:  # each road user's largest sideways drift in this run
            back = np.maximum(s[others, 0] - s[others].min(axis=1), 0.0)
            drift[: len(others)] = np.minimum(iv.drift_rate * back, iv.drift_cap)
        for (track, heading, name), side in zip(tracks, drift, strict=True):
            near = np.flatnonzero(np.hypot(*(track - points[ego]).T) < length + width + side)
            hit = rectangles_intersect(
                track[near], heading[near], points[ego, near], pose[ego, near, 2], length, width + side
            )
            if hit.any():
                return Rollout(False, f"{run} run: {name} at {float(until[near[np.argmax(hit)]]) * dt:.2f} s")
    return Rollout(True, speed=speed)
