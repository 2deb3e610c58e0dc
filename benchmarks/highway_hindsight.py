r"""A reference with hindsight for the intersection: the best wait-then-go schedule, found by
simulating the episode's own future.

:class:`HindsightEgo` is no planner: at the episode's start it copies the simulator (the traffic's
random draws included, so each copy lives the same future) and tries the schedules "wait at the
stop line until $t_0$, then go", $t_0 = 0, T, 2T, \dots$ up to the episode's end, each on its own
copy; the ego of the first schedule that reaches the goal without a collision then drives the real
episode, which repeats that copy's future exactly. Where none does, the ego waits at the line for
the whole episode.

The ego is highway-env's ``IDMVehicle`` on the route (the traffic's own driver: its speed, its
following, its acceleration of up to 6 m/s^2 at the intersection), with two changes: it never
yields (the schedule decides when it goes), and while it waits it follows a virtual stopped car
whose rear is at the junction's entry, so it stops with its front there.

What it tells: how often a collision-free passage within the episode exists at all for a driver
that waits and then goes, against which the planners' goal rates can be read. It knows what no
planner can (the traffic's future, which depends on the random route and behaviour each vehicle
draws), so its rates bound from above what a planner of this kind could reach, on the same seeds.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np

from risk_env.highway.common import unwrapped_highway
from risk_env.highway.idm import IDMEgo, put_ego, reached
from risk_env.highway.route import JUNCTION_PREFIX  # a lane to such a node ends at the entry


def scheduled_vehicle(
    base: Any, go_at: float, destination: str, accel: float | None = None, speed: float | None = None
) -> Any:
    """A copy of ``base``'s controlled vehicle as the schedule's driver to ``destination``, waiting at
    the stop line for ``go_at`` simulation frames from now (inf: throughout; see the module);
    ``accel`` [m/s^2] and ``speed`` [m/s]: its IDM's largest comfortable acceleration and its
    desired speed (None: highway-env's traffic's, and the lanes' limit)."""
    from highway_env.vehicle.behavior import IDMVehicle
    from highway_env.vehicle.kinematics import Vehicle

    class Scheduled(IDMVehicle):
        """highway-env's IDM on the route that never yields and waits for :attr:`go_at` frames of
        its own clock (frames since it was placed)."""

        def act(self, action: Any = None) -> None:
            cap = math.inf if speed is None else speed  # never yields: the schedule decides
            self.target_speed = min(self.lane.speed_limit, cap)
            super().act(action)

        def step(self, dt: float) -> None:
            self.clock += 1  # once per simulation frame (act() also runs on the policy's frames)
            super().step(dt)

        def acceleration(
            self, ego_vehicle: Any, front_vehicle: Any = None, rear_vehicle: Any = None
        ) -> float:
            a = super().acceleration(ego_vehicle, front_vehicle, rear_vehicle)
            waiting = ego_vehicle is self and self.clock < self.go_at
            if waiting and self.lane_index[1].startswith(JUNCTION_PREFIX):
                lane = self.road.network.get_lane(self.lane_index)
                s = lane.length - self.LENGTH / 2 + self.DISTANCE_WANTED  # IDM stops d0 behind it
                line = Vehicle(self.road, lane.position(s, 0.0), lane.heading_at(lane.length), 0.0)
                a = min(a, super().acceleration(self, line, None))
            return float(a)

    old = base.vehicle
    ego = Scheduled(base.road, old.position.copy(), heading=old.heading, speed=old.speed)
    ego.plan_route_to(destination)
    ego.go_at, ego.clock = go_at, 0
    if accel is not None:
        ego.COMFORT_ACC_MAX = float(accel)
    return ego


def outcome(sim: Any, destination: str) -> tuple[bool, bool]:
    """Run ``sim`` (an unwrapped copy) to its episode's end: ``(collision, goal)``."""
    action = np.zeros(sim.action_space.shape, dtype=np.float32)
    done = False
    while not done:
        _, _, terminated, truncated, _ = sim.step(action)
        done = terminated or truncated
    return bool(sim.vehicle.crashed), bool(reached(sim, destination))


class HindsightEgo(IDMEgo):
    """The reference with hindsight (see the module); like :class:`risk_env.highway.IDMEgo` it drives
    ``env``'s controlled vehicle itself, whatever action is passed (``predict`` returns a zero
    action). ``reset()`` after each ``env.reset`` searches the schedules (:attr:`start`: the chosen
    $t_0$ [s], inf: waits throughout; :attr:`tried`: schedules simulated)."""

    def __init__(self, env: Any, destination: str | None = None) -> None:
        super().__init__(env, destination)
        self.start = math.inf
        self.tried = 0

    def reset(self) -> None:
        """Search the schedules on copies of the episode just reset, and drive the first that
        reaches the goal without a collision (else wait)."""
        self._take_over(unwrapped_highway(self.env))

    def _take_over(self, base: Any) -> None:
        period = 1.0 / base.config["policy_frequency"]
        frames = int(base.config["simulation_frequency"] // base.config["policy_frequency"])
        self.start, self.tried = math.inf, 0
        # one copy waits throughout; at each step a copy of it goes, until one arrives unharmed
        waiting = copy.deepcopy(base)
        put_ego(waiting, scheduled_vehicle(waiting, math.inf, self.destination))
        idle = np.zeros(waiting.action_space.shape, dtype=np.float32)
        for step in range(math.ceil(base.config["duration"] / period)):
            branch = copy.deepcopy(waiting)
            branch.vehicle.go_at = branch.vehicle.clock
            self.tried += 1
            crashed, goal = outcome(branch, self.destination)
            if goal and not crashed:
                self.start = step * period
                break
            _, _, terminated, truncated, _ = waiting.step(idle)
            if terminated or truncated:
                break
        go_at = math.inf if math.isinf(self.start) else round(self.start / period) * frames
        self._vehicle = scheduled_vehicle(base, go_at, self.destination)
        put_ego(base, self._vehicle)
