r"""The lane predictor's route weights: a prior over the turns, updated by what is observed.

For a road user measured at position $p$ [m], direction of travel $\theta$ [rad], speed $v$ [m/s]
and turn rate $\omega$ [rad/s], each route $r$ it can take
(:func:`~risk_env.highway.lanes.routes.routes_from`) gets the weight

$$
w_r \propto \mathrm{prior}(\text{turn of } r)\, L(o_r)\, L(h_r)\, L(\dot h_r)
$$

- $o_r$: $p$'s lateral offset [m] from $r$'s centreline (:meth:`Route.locate
  <risk_env.highway.lanes.routes.Route.locate>`);
- $h_r$: $\theta$ minus $r$'s heading there [rad];
- $\dot h_r$: $\omega$ minus the turn rate highway-env's own lane keeping
  (``ControlledVehicle.steering_control``) gives a vehicle in this state that follows $r$
  (:func:`steering_turn_rates`): it steers for the next lane of its route from half a vehicle length
  before the end of a lane on, so the turn rate tells the route a step before the junction;
- $L(e) = (1 - \eta)\, \mathcal{N}(e; 0, \sigma) + \eta\, \mathcal{N}(e; 0, c \sigma)$ ($\eta$ =
  ``outlier``, $c$ = ``outlier_scale``): a Gaussian with a wide tail, so that one odd observation
  cannot rule a route out;
- below ``reliable_speed`` the heading term is left out and the turn rate's $\sigma$ grows (at low
  speed highway-env's steering saturates and the body turns on the spot).

Where the routes share the lane the road user is on and its lane keeping does not yet steer for a
turn, the terms are the same for each and the prior decides; from half a vehicle length before
the junction on, its turn rate, then its heading and offset, single its route out. The **prior**
(``turn_prior``) weighs the turns left, straight and right, by the route's heading change over its
first fork lane (a lane chosen among two or more that leave one node): right for more than +45
degrees, left for less than -45, else straight, as highway-env draws its roads (y downward on the
screen, so a turn toward +heading is a right turn, the tight one in its right-hand traffic);
highway-env's traffic picks its exit uniformly, so the default is uniform. The $\sigma$s were chosen
on the benchmark's seeds 0-11 (``python -m benchmarks.prediction --episodes 12``) for a low Brier
score in the junction with no true route's weight below the planner's threshold; the benchmark's
committed run uses other seeds.

**The turn signal** (optional): highway-env's ``observe_intentions`` observes the unit vector from a
vehicle to its destination (the end of its route). Given it, a route's weight is also multiplied
by ``L(angle between that vector and the direction to r's end)`` with ``sigma_signal``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from risk_env.highway.lanes.routes import Route, next_lanes, wrap

TURNS = ("left", "straight", "right")
"""The turn kinds the prior weighs."""


@dataclass(frozen=True)
class WeightModel:
    """The numbers of the route weights (see the module docstring)."""

    turn_prior: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """Prior weights of a left turn, straight on and a right turn (normalised over the routes)."""
    sigma_offset: float = 0.2
    r"""$\sigma$ [m] of the lateral offset from a route's centreline."""
    sigma_heading: float = 0.3
    r"""$\sigma$ [rad] of the heading against a route's."""
    sigma_turn_rate: float = 0.05
    r"""$\sigma$ [rad/s] of the turn rate against the one highway-env's lane keeping gives on a route."""
    switch_time: float = 0.1
    """Within this time [s] (at the road user's speed) of the point where highway-env's lane keeping
    switches to a route's next lane, both lanes' turn rates are taken (the better one counts)."""
    outlier: float = 0.02
    """Share of the wide component in each term."""
    outlier_scale: float = 30.0
    """Its width, in standard deviations."""
    reliable_speed: float = 2.0
    r"""Below this speed [m/s] the heading says nothing (the term is left out) and the turn rate's
    $\sigma$ grows as ``reliable_speed`` $/ |v|$: highway-env's lane keeping saturates its steering at
    low speed and the body turns on the spot."""
    sigma_signal: float = 0.1
    r"""$\sigma$ [rad] of the turn signal's direction against a route's end (``observe_intentions``)."""

    def __post_init__(self) -> None:
        prior = self.turn_prior
        if len(prior) != 3 or not all(
            isinstance(p, (int, float)) and math.isfinite(p) and p >= 0 for p in prior
        ):
            raise ValueError(
                f"WeightModel.turn_prior must be 3 finite numbers >= 0 (left, straight, right), got {prior!r}"
            )
        if sum(prior) <= 0:
            raise ValueError(f"WeightModel.turn_prior must not be all zero, got {prior!r}")
        for name in (
            "sigma_offset",
            "sigma_heading",
            "sigma_turn_rate",
            "outlier_scale",
            "sigma_signal",
            "reliable_speed",
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"WeightModel.{name} must be a finite number > 0, got {value!r}")
        if not (0.0 <= self.outlier < 1.0):
            raise ValueError(f"WeightModel.outlier must lie in [0, 1), got {self.outlier!r}")

    def log_term(self, error: float, sigma: float) -> float:
        """``log L(error)`` for a term of standard deviation ``sigma`` (constants that are the same
        for every route dropped)."""
        wide = self.outlier_scale * sigma
        core = (1 - self.outlier) * math.exp(-0.5 * (error / sigma) ** 2) / sigma
        tail = self.outlier * math.exp(-0.5 * (error / wide) ** 2) / wide
        return math.log(core + tail)


def turn_of(route: Route) -> str:
    """The turn of ``route`` at its first fork (see the module docstring): on its first lane
    chosen among two or more that leave the same node (the first lane itself when its start node
    has several roads); ``"straight"`` when it has no fork."""
    network = route.network
    for k, index in enumerate(route.lanes):
        choices = len(network.graph[index[0]]) if k == 0 else len(next_lanes(network, route.lanes[k - 1]))
        if choices > 1:
            start, end = route.offsets[k], route.offsets[k] + route.lengths[k]
            change = float(wrap(route.heading(end) - route.heading(start)))
            return "right" if change > math.pi / 4 else "left" if change < -math.pi / 4 else "straight"
    return "straight"


def destination(route: Route) -> np.ndarray:
    """The end [m] ``(2,)`` of ``route`` continued while it has exactly one continuation (an
    approach and its turn continue into the exit): where highway-env's turn signal points."""
    network = route.network
    index = route.lanes[-1]
    seen = set(route.lanes)
    while True:
        following = next_lanes(network, index)
        if len(following) != 1 or following[0] in seen:
            break
        index = following[0]
        seen.add(index)
    lane = network.get_lane(index)
    return np.asarray(lane.position(lane.length, 0.0), dtype=float)


def steering_turn_rates(route: Route, measurement: Any, switch_time: float) -> list[float]:
    r"""The turn rates [rad/s] highway-env's lane keeping (``ControlledVehicle.steering_control``,
    called as it is) gives a vehicle at ``measurement`` $= (x, y, \theta, v, \omega)$ that follows
    ``route``: it steers toward the route's lane it targets and turns at $v \sin(\beta) / (l / 2)$
    (slip angle $\beta$, length $l$). It targets the next lane from half a vehicle length before a
    lane's end on (as ``follow_road`` switches); within ``switch_time`` [s] of that point, both
    lanes (the turn rate was set a simulation frame before the measurement). The body heading is
    $\theta$ less the slip angle that $\omega$ implies."""
    from highway_env.vehicle.controller import ControlledVehicle

    x, y, theta, v, omega = (float(c) for c in measurement)
    half = ControlledVehicle.LENGTH / 2
    beta = math.asin(max(-1.0, min(1.0, omega * half / v))) if abs(v) > 1e-6 else 0.0
    point = np.array([x, y])
    s = route.locate(point)[0]
    k = int(route.lane_of(s))
    margin = abs(v) * switch_time
    targets = []
    for shift in (-margin, 0.0, margin):
        j = k
        while j < len(route.lanes) - 1 and s + shift - route.offsets[j] > route.lengths[j] - half:
            j += 1
        if j not in targets:
            targets.append(j)
    state = SimpleNamespace(
        road=SimpleNamespace(network=route.network), position=point, speed=v, heading=theta - beta
    )
    out = []
    for j in targets:
        steering = ControlledVehicle.steering_control(_Controller(state), route.lanes[j])
        out.append(v * math.sin(math.atan(0.5 * math.tan(steering))) / half)
    return out


class _Controller(SimpleNamespace):
    """A vehicle's state with highway-env's ``ControlledVehicle`` gains, for its ``steering_control``."""

    def __init__(self, state: SimpleNamespace) -> None:
        from highway_env.vehicle.controller import ControlledVehicle

        names = ("LENGTH", "TAU_PURSUIT", "KP_LATERAL", "KP_HEADING", "MAX_STEERING_ANGLE")
        super().__init__(**vars(state), **{name: getattr(ControlledVehicle, name) for name in names})


def route_weights(
    model: WeightModel,
    routes: list[Route],
    turns: list[str],
    measurement: Any,
    signal: np.ndarray | None = None,
) -> np.ndarray:
    """The weights ``(R,)`` (summing to 1) of ``routes`` for a road user at ``measurement = (x, y,
    theta, v, omega)``; ``turns``: each route's turn (:func:`turn_of`); ``signal``: the turn signal
    (a unit vector ``(2,)``) or None."""
    x, y, theta, v, omega = (float(c) for c in measurement)
    point = np.array([x, y])
    prior = dict(zip(TURNS, model.turn_prior, strict=True))
    slow = max(1.0, model.reliable_speed / max(abs(v), 1e-3))
    logs = np.empty(len(routes))
    for i, (route, turn) in enumerate(zip(routes, turns, strict=True)):
        weight = prior[turn]
        if weight <= 0:
            logs[i] = -math.inf
            continue
        s, r = route.locate(point)
        heading = float(wrap(theta - float(route.heading(s))))
        rates = steering_turn_rates(route, measurement, model.switch_time)
        total = math.log(weight)
        total += model.log_term(r, model.sigma_offset)
        if abs(v) >= model.reliable_speed:
            total += model.log_term(heading, model.sigma_heading)
        total += max(model.log_term(omega - rate, model.sigma_turn_rate * slow) for rate in rates)
        if signal is not None:
            aim = destination(route) - point
            angle = float(wrap(math.atan2(signal[1], signal[0]) - math.atan2(aim[1], aim[0])))
            total += model.log_term(angle, model.sigma_signal)
        logs[i] = total
    if not np.isfinite(logs).any():
        return np.full(len(routes), 1.0 / len(routes))
    w = np.exp(logs - logs.max())
    return w / w.sum()
