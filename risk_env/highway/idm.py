"""highway-env's own driver as the reference of :mod:`risk_env.highway.adapter`, and the goal test."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from risk_env.highway.common import unwrapped_highway


class IDMEgo:
    """highway-env's own driver as a reference: at the start of each episode the controlled vehicle
    is replaced by the env's ``other_vehicles_type`` (``IDMVehicle``) at the same state, routed to
    ``destination``; it then drives itself (IDM speed, lane keeping, the intersection's yielding
    rules), whatever action is passed. ``predict`` returns a zero action."""

    def __init__(self, env: gym.Env, destination: str | None = None) -> None:
        self.env = env
        base = unwrapped_highway(env)
        self.destination = destination or base.config.get("destination")
        if not self.destination:
            raise ValueError("no destination: pass destination= or set the env's config['destination']")
        self._vehicle: Any = None
        self.last_solve = None

    def reset(self) -> None:
        self._vehicle = None

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[np.ndarray, None]:
        base = unwrapped_highway(self.env)
        if base.vehicle is not self._vehicle:
            self._take_over(base)
        return np.zeros(self.env.action_space.shape, dtype=np.float32), None

    def _take_over(self, base: Any) -> None:
        from highway_env import utils

        old = base.vehicle
        cls = utils.class_from_path(base.config["other_vehicles_type"])
        idm = cls(base.road, old.position.copy(), heading=old.heading, speed=old.speed)
        idm.plan_route_to(self.destination)
        put_ego(base, idm)
        self._vehicle = idm


def put_ego(base: Any, vehicle: Any) -> None:
    """Make ``vehicle`` the controlled vehicle of the unwrapped highway-env ``base`` in place of the
    current one (on the road and among the controlled vehicles)."""
    old = base.vehicle
    base.road.vehicles[base.road.vehicles.index(old)] = vehicle
    base.controlled_vehicles[base.controlled_vehicles.index(old)] = vehicle


def reached(env: gym.Env, destination: str) -> bool:
    """Whether the controlled vehicle has arrived on the road to ``destination``: highway-env's
    ``has_arrived`` (25 m into an exit lane) on that destination's exit (``has_arrived`` alone
    accepts any exit)."""
    base = unwrapped_highway(env)
    vehicle = base.vehicle
    arrived = base.has_arrived(vehicle) if hasattr(base, "has_arrived") else True
    return bool(arrived and vehicle.lane_index[1] == destination)
