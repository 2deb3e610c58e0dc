"""Recording ``intersection-v2`` episodes and scoring predictions against them, for
``python -m benchmarks.prediction`` (see there for the metrics)."""

from __future__ import annotations

from typing import Any

import numpy as np

PHASES = ("all", "approach", "junction", "exit", "crashed")
"""The phases of a vehicle's path the benchmark reports (``all``: the first three)."""
ROLLING_BACK = -0.05
"""Speed [m/s] below which a vehicle rolls back: a sample is also scored in the phase
``reversing`` when its vehicle does at the prediction or at any step up to the scored one."""
STEPS = 6
"""Prediction steps scored (3 s at T = 0.5 s)."""
KEYS = ("phase", "n", "err", "covered", "area", "chebyshev", "brier", "fallback", "reversing")
"""The columns of the scored samples (:func:`score_episode`)."""


# ---------------------------------------------------------------------- recording
def phase_of(lane_index: tuple[str, str, int]) -> str:
    """``approach`` (o -> ir), ``junction`` (ir -> il) or ``exit`` (il -> o) of an intersection lane."""
    start = lane_index[0]
    return "approach" if start.startswith("o") else "junction" if start.startswith("ir") else "exit"


def route_nodes(route: Any) -> tuple[str, ...]:
    """A highway-env route (list of lane indices) as its nodes, e.g. ``("o0", "ir0", "il1", "o1")``."""
    if not route:
        return ()
    return (route[0][0], *(index[1] for index in route))


def record_episode(env: Any, seed: int) -> list[dict[str, Any]]:
    """One episode of ``env`` (config ``duration`` set) driven by :class:`IDMEgo`: per step, every
    vehicle's id, measurement, lane, crash flag, turn signal and route (read here for scoring only)."""
    from risk_env.highway import IDMEgo, vehicle_measurement

    ego = IDMEgo(env)
    obs, _ = env.reset(seed=seed)
    ego.reset()
    base = env.unwrapped
    steps: list[dict[str, Any]] = []
    while True:
        action, _ = ego.predict(obs)
        vehicles = list(base.road.vehicles)
        steps.append(
            {
                "ids": [id(v) for v in vehicles],
                "ego": [v is base.vehicle for v in vehicles],
                "m": np.array([vehicle_measurement(v) for v in vehicles]),
                "lane": [tuple(v.lane_index) for v in vehicles],
                "crashed": np.array([bool(v.crashed) for v in vehicles]),
                "signal": np.array([v.destination_direction for v in vehicles], dtype=float),
                "route": [route_nodes(getattr(v, "route", None)) for v in vehicles],
            }
        )
        obs, _, _, truncated, _ = env.step(action)
        if truncated:
            return steps


# ---------------------------------------------------------------------- scoring
def _inside(mode: Any, n: int, point: np.ndarray) -> tuple[bool, float]:
    """Whether ``point`` lies in ``mode``'s truncation box at step ``n`` (in its frame), and the
    box's area [m^2]."""
    from risk_env.models.frame import to_frame

    b = mode.beliefs[n]
    along, across = to_frame(point[0] - float(b.x), point[1] - float(b.y), float(b.frame))
    hx, hy = float(b.half_x), float(b.half_y)
    return bool(abs(along) <= hx and abs(across) <= hy), 4.0 * hx * hy


def brier(mixture: Any, taken: tuple[str, ...]) -> float:
    """The Brier score of ``mixture``'s route weights against the route ``taken`` (its nodes); NaN
    when its modes carry no routes."""
    weights: dict[str, float] = {}  # a route's weight over its modes (held and free are one route)
    for mode in mixture:
        for label, w in getattr(mode, "routes", ()):
            weights[label] = weights.get(label, 0.0) + w
    routes = list(weights.items())
    if not routes:
        return float("nan")
    joined = ">" + ">".join(taken) + ">"
    return float(sum((w - float((">" + label + ">") in joined)) ** 2 for label, w in routes))


def true_routes(steps: list[dict[str, Any]]) -> dict[int, tuple[str, ...]]:
    """Each vehicle's route as its nodes: its route when first seen (highway-env drops a lane from
    it as the vehicle ends that lane), after the node its lane then started from."""
    out: dict[int, tuple[str, ...]] = {}
    for step in steps:
        for vid, lane, nodes in zip(step["ids"], step["lane"], step["route"], strict=True):
            if vid not in out:
                out[vid] = (lane[0], *nodes) if nodes and lane[1] == nodes[0] else nodes
    return out


def score_episode(
    steps: list[dict[str, Any]], predictors: dict[str, Any], threshold: float
) -> dict[str, np.ndarray]:
    """Per predictor, the scored samples of one recorded episode: columns ``phase`` (index into
    :data:`PHASES`), ``n``, ``err``, ``covered``, ``area``, ``chebyshev``, ``brier``, ``fallback``,
    ``reversing`` (the vehicle rolls back by then, :data:`ROLLING_BACK`)."""
    from risk_env.highway.lanes.predictor import LaneMode

    out: dict[str, list[tuple]] = {name: [] for name in predictors}
    where = [{vid: k for k, vid in enumerate(step["ids"])} for step in steps]
    taken = true_routes(steps)
    for t, step in enumerate(steps):
        for name, predictor in predictors.items():
            signals = step["signal"] if name == "lane+signal" else None
            kwargs = {"signals": signals} if signals is not None else {}
            mixtures = predictor.predict_scene(step["m"], STEPS, **kwargs)
            for k, vid in enumerate(step["ids"]):
                if step["ego"][k]:
                    continue
                mixture = mixtures[k]
                best = mixture.most_likely()
                kept = mixture.above(threshold)
                fallback = name != "constant" and not isinstance(best, LaneMode)
                score = brier(mixture, taken[vid]) if name != "constant" else float("nan")
                phase = PHASES.index(phase_of(step["lane"][k]))
                rolled = step["m"][k, 3] < ROLLING_BACK
                for n in range(1, STEPS + 1):
                    if t + n >= len(steps) or vid not in where[t + n]:
                        break
                    j = where[t + n][vid]
                    rolled = rolled or steps[t + n]["m"][j, 3] < ROLLING_BACK
                    truth = steps[t + n]["m"][j, :2]
                    crashed = bool(step["crashed"][k] or steps[t + n]["crashed"][j])
                    mean = np.array([float(best.beliefs.x[n]), float(best.beliefs.y[n])])
                    inside = [_inside(mode, n, truth) for mode in kept]
                    out[name].append(
                        (
                            PHASES.index("crashed") if crashed else phase,
                            n,
                            float(np.hypot(*(truth - mean))),
                            any(i for i, _ in inside),
                            sum(a for _, a in inside),
                            float(np.max(np.abs(truth - mean))),
                            score,
                            fallback,
                            bool(rolled),
                        )
                    )
    return {
        name: {key: np.array([row[i] for row in rows]) for i, key in enumerate(KEYS)} if rows else {}
        for name, rows in out.items()
    }


def make_predictors(
    names: list[str], env: Any, uncertainty: str, interval: tuple[str, ...] = ()
) -> dict[str, Any]:
    """The predictors ``names`` for ``env`` (its road network, its step); ``interval``: the
    switches of ``lane+interval``'s :class:`~risk_env.highway.lanes.interval.IntervalModel` to turn
    on."""
    from benchmarks.highway_agents import interval_model
    from risk_env.highway import LanePredictor, highway_scenario, policy_period
    from risk_env.prediction import ConstantPredictor

    out: dict[str, Any] = {}
    for name in names:
        if name == "constant":
            out[name] = ConstantPredictor(highway_scenario(env, uncertainty))
        elif name == "lane+interval":  # the ego is one of the recorded scene's road users
            intervals = interval_model(interval)
            out[name] = LanePredictor(
                env.unwrapped.road.network, policy_period(env), longitudinal="interval", intervals=intervals
            )
        else:
            out[name] = LanePredictor(env.unwrapped.road.network, policy_period(env))
    return out
