r"""What the wrapper, the adapter and the graphics share: highway-env's import, its step length, a
vehicle as our unicycle measurement, and the scenario that carries our numbers into its world.

Frames: we use highway-env's world coordinates as they are, $(c_1, c_2) = (x, y)$ [m] and headings
[rad] from the x axis toward y. highway-env moves its vehicles with
$\dot q = v\, (\cos, \sin)(\psi + \beta)$ (heading $\psi$, slip angle $\beta$), the same equations
as our unicycle, so every formula of :mod:`risk_env` holds there unchanged (highway-env's screen
shows y downward: a mirror image, nothing more).
"""

from __future__ import annotations

import importlib
import math
import warnings
from types import ModuleType
from typing import Any

import numpy as np

from risk_env.scenario.scenario import Scenario

SPEED_BOUND = 40.0
"""Speed truncation [m/s] of the object's prediction in highway-env worlds, ``(-40, 40)``: the
paper's ``(-5, 5)`` would not contain highway speeds. 40 m/s is highway-env's ``Vehicle.MAX_SPEED``."""

INSTALL_HINT = "pip install 'riskcrossing[render]'"


def require_highway_env() -> ModuleType:
    """``import highway_env``, or an ImportError that says how to install it."""
    try:
        return importlib.import_module("highway_env")
    except ImportError as exc:
        raise ImportError(
            f"risk_env.highway needs highway-env (with pygame-ce): {INSTALL_HINT}. The rest of"
            f" risk_env works without it. ({exc})"
        ) from exc


def unwrapped_highway(env: Any) -> Any:
    """The highway-env ``AbstractEnv`` under ``env``'s wrappers; a clear error for anything else."""
    base = getattr(env, "unwrapped", env)
    missing = [name for name in ("controlled_vehicles", "road", "config") if not hasattr(base, name)]
    if missing:
        raise TypeError(
            f"expected a highway-env environment (with controlled_vehicles, road and config), got"
            f" {type(base).__name__} without {', '.join(missing)}"
        )
    return base


def policy_period(env: Any) -> float:
    """Duration [s] of one ``env.step``: ``simulation_frequency // policy_frequency`` frames of
    ``1 / simulation_frequency`` s each (1 s for highway-env's defaults)."""
    config = unwrapped_highway(env).config
    frames = int(config["simulation_frequency"] // config["policy_frequency"])
    if frames < 1:
        raise ValueError(
            f"policy_frequency {config['policy_frequency']} Hz exceeds simulation_frequency"
            f" {config['simulation_frequency']} Hz"
        )
    return frames / config["simulation_frequency"]


def slip_angle(steering: float) -> float:
    """beta [rad] of highway-env's kinematic bicycle: the angle between heading and velocity for a
    front steering angle ``steering`` [rad]: ``atan(tan(steering) / 2)``."""
    return math.atan(0.5 * math.tan(steering))


def bicycle_curvature(base: Any) -> float:
    r"""The largest curvature [1/m] of the course of the unwrapped env ``base``'s controlled car at
    full lock: $\sin\beta_{max} / (l / 2)$, $\beta_{max}$ the slip angle (:func:`slip_angle`) of its
    action's largest steering angle and $l$ its length (the kinematic bicycle turns at
    $\omega = v \sin\beta / (l / 2)$)."""
    steering = max(abs(float(a)) for a in base.action_type.steering_range)
    return math.sin(slip_angle(steering)) / (0.5 * float(base.action_type.vehicle_class.LENGTH))


def vehicle_measurement(vehicle: Any) -> np.ndarray:
    r"""A highway-env vehicle as our unicycle measurement $(c_1, c_2, \theta, v, \omega)$ [m, m, rad,
    m/s, rad/s], ``(5,)`` float64.

    $\theta$ is the direction of travel (heading plus slip angle) and $\omega$ its rate, so that our
    unicycle with these inputs moves the vehicle's centre exactly as highway-env does while the
    vehicle keeps its speed and steering: for the kinematic ``Vehicle`` (and the IDM/MDP vehicles
    built on it) $\beta = \arctan(\tan(\delta) / 2)$, $\omega = v \sin(\beta) / (l / 2)$ (steering
    $\delta$, length $l$); for the dynamic ``BicycleVehicle`` the slip comes from its lateral speed and
    $\omega$ is its yaw rate.
    """
    x, y = (float(c) for c in vehicle.position)
    heading, speed = float(vehicle.heading), float(vehicle.speed)
    if hasattr(vehicle, "lateral_speed") and hasattr(vehicle, "yaw_rate"):  # BicycleVehicle
        lateral = float(vehicle.lateral_speed)
        # theta stays within pi/2 of the heading; a reversing vehicle keeps a negative speed
        beta = math.atan(lateral / speed) if abs(speed) > 1e-9 else 0.0
        ground = math.copysign(math.hypot(speed, lateral), speed)
        return np.array([x, y, heading + beta, ground, float(vehicle.yaw_rate)])
    action = getattr(vehicle, "action", None) or {}
    steering = 0.0 if getattr(vehicle, "crashed", False) else float(action.get("steering", 0.0))
    beta = slip_angle(steering)
    omega = speed * math.sin(beta) / (0.5 * float(vehicle.LENGTH))
    return np.array([x, y, heading + beta, speed, omega])


def highway_scenario(
    env: Any, uncertainty: str = "low", risk_tolerance: float = 0.0, **overrides: Any
) -> Scenario:
    """The paper's scenario at an uncertainty preset, carried into ``env``'s world.

    Set from the env: ``dt`` = :func:`policy_period` (the prediction steps are env steps, so a
    preset's growth per step is growth per env step). Changed from the paper:
    ``velocity_bounds0 = (-SPEED_BOUND, SPEED_BOUND)``. Everything else is the paper's unless
    overridden by flat name (:data:`risk_env.scenario.scenario.OVERRIDES`), e.g. ``ego_radius=2.0``,
    ``severity="plastic"``. Positions and the path in the scenario are not used by the wrapper.
    """
    values: dict[str, Any] = {"dt": policy_period(env), "velocity_bounds0": (-SPEED_BOUND, SPEED_BOUND)}
    values.update(overrides)
    return Scenario.preset(uncertainty, risk_tolerance=risk_tolerance, **values)


def check_adapter_config(base: Any) -> None:
    """Raise ``ValueError`` with a hint unless the unwrapped highway-env ``base`` has what
    :class:`~risk_env.highway.adapter.IntersectionAdapter` needs: continuous throttle and steering on
    the kinematic vehicle, absolute unnormalised Kinematics observations with headings."""
    from highway_env.envs.common.action import ContinuousAction
    from highway_env.envs.common.observation import KinematicObservation

    hint = "build the env with risk_env.highway.make_intersection_env() (INTERSECTION_CONFIG)"
    action = base.action_type
    if type(action) is not ContinuousAction or not (action.longitudinal and action.lateral):
        raise ValueError(
            f"the adapter needs highway-env's ContinuousAction with throttle and steering, got"
            f" {type(action).__name__}; {hint}"
        )
    if action.dynamical:
        raise ValueError(f"the adapter needs the kinematic vehicle ('dynamical': False); {hint}")
    obs = base.observation_type
    needed = {"presence", "x", "y", "vx", "vy", "heading"}
    if not isinstance(obs, KinematicObservation) or not needed <= set(obs.features):
        raise ValueError(f"the adapter needs a Kinematics observation with features {sorted(needed)}; {hint}")
    if not obs.absolute or obs.normalize:
        raise ValueError(f"the adapter needs absolute, unnormalised Kinematics observations; {hint}")


SIGNAL_FEATURES = ("cos_d", "sin_d")
"""highway-env's Kinematics features of a vehicle's turn signal: the unit vector from it to its
destination, observed with ``observe_intentions`` (else 0)."""


def signal_observation(observation: dict[str, Any]) -> dict[str, Any]:
    """The Kinematics ``observation`` config that also observes the other vehicles' turn signals
    (:data:`SIGNAL_FEATURES`, ``observe_intentions``)."""
    features = [f for f in observation["features"] if f not in SIGNAL_FEATURES]
    return {**observation, "features": [*features, *SIGNAL_FEATURES], "observe_intentions": True}


def turn_signals(base: Any, observation: Any) -> list[np.ndarray | None] | None:
    """The observed turn signals (``(2,)`` each, None where it shows none) of the other present
    rows of highway-env's Kinematics ``observation`` (in the adapter's order), or None when the env
    (``base``, unwrapped) does not observe them (:func:`signal_observation`)."""
    kind = base.observation_type
    features = list(kind.features)
    if not getattr(kind, "observe_intentions", False) or not set(SIGNAL_FEATURES) <= set(features):
        return None
    obs = np.asarray(observation, dtype=float)
    present = obs[:, features.index("presence")] > 0.5
    present[0] = True
    rows = obs[present][1:]
    vectors = rows[:, [features.index(f) for f in SIGNAL_FEATURES]]
    return [v if np.hypot(*v) > 1e-9 else None for v in vectors]


INTERSECTION_CONFIG: dict[str, Any] = {
    "action": {
        "type": "ContinuousAction",
        "longitudinal": True,
        "lateral": True,
        "dynamical": False,
        "steering_range": [-math.pi / 3, math.pi / 3],
    },
    "observation": {
        "type": "Kinematics",
        "vehicles_count": 15,
        "features": ["presence", "x", "y", "vx", "vy", "heading"],
        "absolute": True,
        "normalize": False,
        "see_behind": True,
        "order": "sorted",
    },
    "policy_frequency": 2,
    "simulation_frequency": 16,
}
"""``intersection-v1`` as the adapter needs it: the kinematic vehicle (highway-env's own default for
``intersection-v1`` is its dynamic bicycle), an unnormalised absolute observation with headings,
and a step of T = 0.5 s (the paper's sample time: 8 frames at 16 Hz). Everything else, including
the traffic, the destination ``"o1"`` (a left turn) and the 13 s duration, is highway-env's."""

VERSIONS: tuple[str, ...] = ("intersection-v2", "intersection-v1")
"""The intersections the adapter drives. ``intersection-v2`` (default): highway-env 1.12 fixed its
traffic's neighbour search there and recommends it for new experiments; ``intersection-v1``: the
earlier traffic, selectable for comparison."""


def make_intersection_env(
    render_mode: str | None = None, version: str = VERSIONS[0], signals: bool = False, **config: Any
) -> Any:
    """``gym.make(version)`` (one of :data:`VERSIONS`) with :data:`INTERSECTION_CONFIG`, updated
    by ``config``; ``signals``: the observation also shows the other vehicles' turn signals
    (:func:`signal_observation`; the adapter passes them to the gate and the agents' lane predictor)."""
    import gymnasium as gym

    if version not in VERSIONS:
        raise ValueError(f"unknown intersection {version!r}; expected one of {VERSIONS}")
    require_highway_env()
    merged = {**INTERSECTION_CONFIG, **config}
    if signals:
        merged["observation"] = signal_observation(merged["observation"])
    with warnings.catch_warnings():  # gymnasium: "intersection-v1 is out of date" (selectable)
        warnings.simplefilter("ignore", DeprecationWarning)
        return gym.make(version, render_mode=render_mode, config=merged)
