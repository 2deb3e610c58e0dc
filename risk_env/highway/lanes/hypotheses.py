"""The lane predictor's route hypotheses as the speed model's agents, and the ego's plan (the
prediction given what the ego will do)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from risk_env import checks
from risk_env.highway.lanes.routes import Route
from risk_env.highway.lanes.speed import Agents


@dataclass
class Hypotheses:
    """One road user's route hypotheses: routes, its arc length and offset on each, their weights,
    and their grouping into modes (indices, labels)."""

    routes: list[Route]
    starts: np.ndarray
    offsets: np.ndarray
    weights: np.ndarray
    groups: list[list[int]]
    labels: list[str]


@dataclass
class Scene:
    """Every road user's route hypotheses as the speed model's agents
    (:meth:`LanePredictor.scene <risk_env.highway.lanes.predictor.LanePredictor.scene>`)."""

    rows: np.ndarray
    """``(m, 5)``: the road users' measurements, the ego's last when it takes part."""
    users: int
    """How many road users are predicted (the ego, when it takes part, is row ``users``)."""
    hypotheses: list[Hypotheses | None]
    """Each row's route hypotheses (None: off the road)."""
    agents: Agents
    """Their routes as the speed model's agents."""
    is_ego: np.ndarray
    """``(A,)`` bool: the agents of the ego."""
    motion: tuple[float, float] | None
    """The ego's ``(accel, speed)`` [m/s², m/s] in a prediction given its plan, else None."""


@dataclass(frozen=True)
class EgoPlan:
    """What the ego will do, for a prediction given it (:meth:`LanePredictor.predict_scene
    <risk_env.highway.lanes.predictor.LanePredictor.predict_scene>`'s
    ``ego_plan``): drive along ``lanes`` (highway-env lane indices, its route), accelerating at
    ``accel`` [m/s²] up to ``speed`` [m/s]."""

    lanes: tuple[tuple[str, str, int], ...]
    accel: float
    speed: float

    def __post_init__(self) -> None:
        if not self.lanes:
            raise ValueError("EgoPlan.lanes must name at least one lane")
        checks.positive("EgoPlan.accel", self.accel)
        checks.positive("EgoPlan.speed", self.speed)


def within(lanes: tuple, route: tuple) -> bool:
    """Whether ``lanes`` run, in order and one after the other, along ``route``."""
    k = len(lanes)
    return any(tuple(route[i : i + k]) == tuple(lanes) for i in range(len(route) - k + 1))


def planned(hyp: Hypotheses, plan: EgoPlan) -> Hypotheses:
    """The ego's hypotheses cut to the routes along ``plan``'s lanes (all, if none is)."""
    keep = [k for k, route in enumerate(hyp.routes) if within(route.lanes, plan.lanes)]
    if not keep:
        return hyp
    weights = np.full(len(keep), 1.0 / len(keep))
    return Hypotheses(
        [hyp.routes[k] for k in keep],
        hyp.starts[keep],
        hyp.offsets[keep],
        weights,
        [list(range(len(keep)))],
        ["plan"],
    )


def agents_of(rows: np.ndarray, hypotheses: list[Hypotheses | None]) -> Agents:
    """The :class:`~risk_env.highway.lanes.speed.Agents` of every road user's route hypotheses (its
    likeliest route its representative; route weights normalised per road user)."""
    vehicle, routes, s, r, v, rep, weight = [], [], [], [], [], [], []
    for i, (row, hyp) in enumerate(zip(rows, hypotheses, strict=True)):
        if hyp is None:
            continue
        best = int(np.argmax(hyp.weights))
        total = float(hyp.weights.sum())
        weight.extend(hyp.weights / total if total > 0 else np.full(len(hyp.weights), 1 / len(hyp.weights)))
        for k, route in enumerate(hyp.routes):
            vehicle.append(i)
            routes.append(route)
            s.append(hyp.starts[k])
            r.append(hyp.offsets[k])
            v.append(row[3])
            rep.append(k == best)
    return Agents(
        np.array(vehicle, dtype=int),
        routes,
        np.array(s, float),
        np.array(r, float),
        np.array(v, float),
        np.array(rep, dtype=bool),
        np.array(weight, float),
    )


def per_user(name: str, values: Any, count: int) -> list[Any]:
    """``values`` (one per road user, or None for all None) as a list of ``count``."""
    if values is None:
        return [None] * count
    values = list(values)
    if len(values) != count:
        raise ValueError(f"{name} must have one entry per road user ({count}), got {len(values)}")
    return values


def turn_signal(signal: Any) -> np.ndarray | None:
    """An observed turn signal ``(2,)`` as a unit vector (None: none, or a zero one)."""
    if signal is None:
        return None
    vector = np.asarray(signal, dtype=float).reshape(-1)
    if vector.shape != (2,):
        raise ValueError(f"a turn signal must be a vector (2,), got {checks.describe(signal)}")
    norm = float(np.hypot(*vector))
    return None if not np.isfinite(norm) or norm < 1e-9 else vector / norm
