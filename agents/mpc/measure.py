"""What an MPC step measures from an observation (:mod:`risk_env.observation`): the state $x_0$,
each present slot's beliefs over the horizon, which slots could matter within the horizon, and
whether the observation continues the episode that the controller remembers."""

from __future__ import annotations

from typing import Any

import numpy as np

from risk_env import observation as ob
from risk_env.models.frame import to_frame
from risk_env.models.ops import NUMPY
from risk_env.models.path import point
from risk_env.prediction.belief import Belief
from risk_env.risk.disc import signed_box_distance
from risk_env.scenario.scenario import Scenario

FREE_MARGIN = 0.5
"""Extra distance [m] the reachable set must keep from every box for the ``"free"`` variant."""


def measured_state(scenario: Scenario, o: ob.Observation) -> np.ndarray:
    r"""$x_0$ ``(NX,)``: the pose with $\theta$ unwrapped near $\theta_P(\lambda_k)$, $\lambda_k$, the
    last input."""
    lam = o.progress
    theta_p = float(point(scenario.path, lam)[2])
    theta = theta_p + float(NUMPY.wrap_angle(o.ego_pose[2] - theta_p))
    return np.array([o.ego_pose[0], o.ego_pose[1], theta, lam, o.ego_input[0], o.ego_input[1]])


def reach(scenario: Scenario, v_last: float) -> np.ndarray:
    r"""Upper bound ``(N,)`` [m] on the distance from the current position to the state $n = 1, \dots, N$,
    from the last speed ``v_last`` [m/s] under the speed bounds and the acceleration limit."""
    ego, dt = scenario.ego, scenario.dt
    cap = max(abs(ego.v_min), abs(ego.v_max))
    speeds = np.minimum(cap, abs(v_last) + ego.accel_max * dt * np.arange(1, scenario.horizon + 1))
    return np.cumsum(speeds) * dt


def risk_possible(scenario: Scenario, x0: np.ndarray, future: Belief, radius: float) -> bool:
    """Whether some step's risk of an object with beliefs ``future`` (and collision distance
    ``radius`` [m]) could be nonzero where the ego can reach from $x_0$ (else its slot is inactive;
    no active slot: the ``"free"`` variant)."""
    along, across = to_frame(x0[0] - future.x, x0[1] - future.y, future.frame)  # the box's frame
    distance = signed_box_distance(along, across, future.half_x, future.half_y)
    spare = distance - reach(scenario, x0[4]) - radius
    return bool(np.any(spare <= FREE_MARGIN))


def new_episode(memory: dict[str, Any], o: ob.Observation) -> bool:
    """The observation does not continue the episode ``memory`` belongs to: its last input is not
    the action returned, or the ego is over 1 m from where the plan put it."""
    if "action" not in memory or np.max(np.abs(o.ego_input - memory["action"])) > 1e-3:
        return True
    return bool(np.hypot(*(o.ego_pose[:2] - memory["predicted"])) > 1.0)
