"""The crossing-object scenario of the paper as one frozen dataclass tree.

Every number of the case study lives here, with its unit. The env, the agents and the benchmarks
all take a :class:`Scenario`; nothing else holds scenario constants.

>>> s = Scenario.preset("medium", v_ref=3.0, risk_tolerance=500.0)
>>> s.uncertainty.sigma_growth
(0.8, 0.8, 0.8)
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from risk_env import checks
from risk_env.observation import POSITION_BOUND, RATE_BOUND

SeverityName = Literal["paper", "plastic", "probability", "injury"]
SEVERITY_NAMES: tuple[str, ...] = ("paper", "plastic", "probability", "injury")
UNCERTAINTY_PRESETS: tuple[str, ...] = ("low", "medium", "high")
RISK_TOLERANCES: tuple[float, ...] = (0.0, 500.0, 1000.0, 1500.0, 2000.0, 2500.0)
"""The paper's risk tolerances epsilon [J] (Table II)."""


def _finite(name: str, value: Any) -> float:
    """``value`` as a float if it is a finite real number, else an error naming ``name``."""
    out = checks.real(name, value)
    if not math.isfinite(out):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return out


def _positive(name: str, value: Any, strict: bool = True) -> float:
    out = _finite(name, value)
    if out < 0 or (strict and out == 0):
        bound = "> 0" if strict else ">= 0"
        raise ValueError(f"{name} must be {bound}, got {value!r}")
    return out


def _triple(name: str, value: Any, length: int = 3) -> tuple[float, ...]:
    out = checks.reals(name, value, length)
    for i, v in enumerate(out):
        _finite(f"{name}[{i}]", v)
    return out


def _set_numbers(owner: Any, prefix: str, names: tuple[str, ...]) -> None:
    """Replace each field in ``names`` of the frozen ``owner`` by its value as a finite float."""
    for name in names:
        object.__setattr__(owner, name, _finite(f"{prefix}{name}", getattr(owner, name)))


@dataclass(frozen=True)
class Pose:
    """A planar configuration ``y = (c1, c2, theta)``."""

    x: float
    """c1 position [m]."""
    y: float
    """c2 position [m]."""
    theta: float
    """Heading [rad], counter-clockwise from the c1 axis."""

    def __post_init__(self) -> None:
        _set_numbers(self, "Pose.", ("x", "y", "theta"))

    @classmethod
    def of(cls, value: Pose | tuple[float, float, float] | Any, name: str = "pose") -> Pose:
        """Build a pose from a ``(x, y, theta)`` sequence, naming ``name`` in errors."""
        if isinstance(value, Pose):
            return value
        return cls(*_triple(name, value))

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.x, self.y, self.theta)


_EGO_NUMBERS = ("radius", "mass", "v_ref", "v_min", "v_max", "omega_max", "accel_max", "omega_rate_max")


@dataclass(frozen=True)
class Ego:
    """The automated (ego) vehicle: a unicycle with input limits.

    The paper leaves the input limits unstated; its RMPC reverses, so ``v_min`` is negative.
    """

    start: Pose = Pose(-10.0, 10.0, 0.0)
    """Initial configuration ``(c1 [m], c2 [m], theta [rad])``; the ego starts at rest."""
    radius: float = 1.5
    """Disc radius r_e [m]."""
    mass: float = 1000.0
    """Mass m_e [kg]."""
    v_ref: float = 4.0
    """Reference speed v_ref [m/s] (the appendix says 3, the velocity figure converges to 4)."""
    initial_input: tuple[float, float] = (0.0, 0.0)
    """Input ``(v [m/s], omega [rad/s])`` applied before the first step."""
    v_min: float = -4.0
    """Lowest speed [m/s] (negative: reversing)."""
    v_max: float = 8.0
    """Highest speed [m/s]."""
    omega_max: float = 0.8
    """Largest turn-rate magnitude [rad/s]."""
    accel_max: float = 3.0
    """Largest speed change per second [m/s^2] (a rate limit on v)."""
    omega_rate_max: float = 1.6
    """Largest turn-rate change per second [rad/s^2] (a rate limit on omega)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", Pose.of(self.start, "ego.start"))
        object.__setattr__(self, "initial_input", _triple("ego.initial_input", self.initial_input, 2))
        _set_numbers(self, "ego.", _EGO_NUMBERS)
        _positive("ego.radius", self.radius)
        _positive("ego.mass", self.mass)
        _positive("ego.v_ref", self.v_ref, strict=False)
        _finite("ego.v_min", self.v_min)
        _positive("ego.v_max", self.v_max)
        if not self.v_min < self.v_max:
            raise ValueError(f"ego.v_min ({self.v_min}) must be below ego.v_max ({self.v_max})")
        if not self.v_min <= self.v_ref <= self.v_max:
            raise ValueError(
                f"ego.v_ref ({self.v_ref}) must lie in [v_min, v_max] = [{self.v_min}, {self.v_max}]"
            )
        _positive("ego.omega_max", self.omega_max)
        _positive("ego.accel_max", self.accel_max)
        _positive("ego.omega_rate_max", self.omega_rate_max)
        v0, w0 = self.initial_input
        if not (self.v_min <= v0 <= self.v_max and abs(w0) <= self.omega_max):
            raise ValueError(f"ego.initial_input {self.initial_input} lies outside the input limits")


@dataclass(frozen=True)
class CrossingObject:
    """The object crossing the path: a unicycle with constant inputs."""

    start: Pose = Pose(5.0, -5.0, math.pi / 2)
    """Initial configuration ``(c1 [m], c2 [m], theta [rad])``."""
    speed: float = 3.0
    """Constant speed input v_o [m/s]."""
    turn_rate: float = 1e-4
    """Constant turn-rate input omega_o [rad/s]."""
    radius: float = 1.5
    """Disc radius r_o [m]."""
    mass: float = 1000.0
    """Mass m_o [kg]."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", Pose.of(self.start, "object.start"))
        _set_numbers(self, "object.", ("speed", "turn_rate", "radius", "mass"))
        _positive("object.radius", self.radius)
        _positive("object.mass", self.mass)


@dataclass(frozen=True)
class Uncertainty:
    """How the object's prediction spreads over the horizon (paper Sec. VI-C, Table I).

    At prediction step n the object's position and speed follow independent truncated Gaussians
    centred on the predicted mean, with standard deviations ``sigma0 + n * sigma_growth`` and a
    truncation box ``mean +- (box_half_width0 + n * box_growth)``; the speed is truncated to
    ``[v_lo0 - n dv, v_hi0 + n dv]``.
    """

    sigma_growth: tuple[float, float, float] = (0.1, 0.1, 0.1)
    """Q: added standard deviation per step for (c1 [m], c2 [m], v [m/s])."""
    box_growth: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """Delta: truncation growth per step and side for (c1 [m], c2 [m], v [m/s])."""
    sigma0: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Sigma_0: standard deviations at the measurement (c1 [m], c2 [m], v [m/s])."""
    box_half_width0: tuple[float, float] = (0.0, 0.0)
    """Half widths of the position truncation box at the measurement (c1 [m], c2 [m])."""
    velocity_bounds0: tuple[float, float] = (-5.0, 5.0)
    """Speed truncation interval at the measurement ``(v_min, v_max)`` [m/s]."""

    def __post_init__(self) -> None:
        for name, length in (
            ("sigma_growth", 3),
            ("box_growth", 3),
            ("sigma0", 3),
            ("box_half_width0", 2),
            ("velocity_bounds0", 2),
        ):
            value = _triple(f"uncertainty.{name}", getattr(self, name), length)
            if name != "velocity_bounds0":
                for i, v in enumerate(value):
                    _positive(f"uncertainty.{name}[{i}]", v, strict=False)
            object.__setattr__(self, name, value)
        lo, hi = self.velocity_bounds0
        if lo > hi:
            raise ValueError(f"uncertainty.velocity_bounds0 must be (low, high), got {(lo, hi)}")

    @classmethod
    def preset(cls, name: str) -> Uncertainty:
        """The paper's Table I: ``"low"``, ``"medium"`` or ``"high"``."""
        table = {"low": (0.1, 1.0), "medium": (0.8, 2.0), "high": (1.5, 3.0)}
        checks.text("uncertainty preset", name, UNCERTAINTY_PRESETS)
        q, delta = table[name]
        return cls(sigma_growth=(q, q, q), box_growth=(delta, delta, delta))


@dataclass(frozen=True)
class ReferencePath:
    """A constant-curvature arc ending at the goal pose (paper appendix).

    ``y_P(lambda)`` for arc length lambda <= 0 ends at ``goal`` for lambda = 0; with the goal
    heading 0: ``c1 = gx + sin(kappa l)/kappa``, ``c2 = gy + (1 - cos(kappa l))/kappa``.
    """

    goal: Pose = Pose(65.0, 5.0, 0.0)
    """Goal configuration y_P(lambda_g) [m, m, rad]."""
    curvature: float = 0.003
    """kappa [1/m]; positive turns left, 0 is a straight line."""
    lambda_start: float = -95.0
    """lambda_0 [m]: the arc length of the path's first point; the goal is at lambda_g = 0."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "goal", Pose.of(self.goal, "path.goal"))
        _set_numbers(self, "path.", ("curvature", "lambda_start"))
        if self.lambda_start >= 0:
            raise ValueError(f"path.lambda_start must be < 0 (goal at 0), got {self.lambda_start}")
        if abs(self.curvature * self.lambda_start) >= math.pi:
            raise ValueError(
                "path.curvature * path.lambda_start must stay within (-pi, pi) so the arc does not"
                f" close on itself, got {self.curvature * self.lambda_start:.3f}"
            )

    @property
    def lambda_goal(self) -> float:
        """lambda_g [m]: always 0, the goal's arc length."""
        return 0.0


@dataclass(frozen=True)
class Scenario:
    """Everything that defines one crossing-object case study.

    Build one with :meth:`preset` (the paper's numbers, with named overrides) or directly.
    """

    ego: Ego = field(default_factory=Ego)
    object: CrossingObject = field(default_factory=CrossingObject)
    uncertainty: Uncertainty = field(default_factory=Uncertainty)
    path: ReferencePath = field(default_factory=ReferencePath)
    dt: float = 0.5
    """Sample time T [s]."""
    horizon: int = 6
    """Prediction horizon N [steps]."""
    cost_weights: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    """Diagonal of W for the stage cost e' W e over (c1 [m], c2 [m], theta [rad], v [m/s])."""
    risk_tolerance: float = 0.0
    """epsilon: the bound on the risk [units of the severity: J for the paper's]."""
    severity: SeverityName = "paper"
    """Severity model: ``"paper"`` (differential kinetic energy), ``"plastic"`` (energy lost in a
    perfectly plastic impact, with velocity vectors), ``"probability"`` (s = 1) or ``"injury"``
    (expected number of seriously injured people, from each party's delta-v)."""
    injury_beta0: float = -4.591
    """Intercept beta0 [-] of the ``"injury"`` severity's logistic MAIS3+ injury probability
    ``1 / (1 + exp(-(beta0 + beta1 delta_v)))``: the model without impact angle of Geisslinger et
    al., "An ethical trajectory planning algorithm for autonomous vehicles", Nature Machine
    Intelligence 5, 2023."""
    injury_beta1: float = 0.185
    """Slope beta1 [s/m] of the same logistic in the delta-v [m/s] (same source); > 0."""
    max_steps: int = 80
    """Episode step limit K [steps]."""
    mc_samples: int = 500
    """J: Monte Carlo samples per risk evaluation."""
    grid_points: int = 40
    """L: grid points per truncation interval for the paper's worst-case grid."""

    def __post_init__(self) -> None:
        for name, cls in (
            ("ego", Ego),
            ("object", CrossingObject),
            ("uncertainty", Uncertainty),
            ("path", ReferencePath),
        ):
            value = getattr(self, name)
            if not isinstance(value, cls):
                raise TypeError(f"scenario.{name} must be a {cls.__name__}, got {checks.describe(value)}")
        object.__setattr__(self, "dt", _positive("dt", self.dt))
        for name, minimum in (("horizon", 1), ("max_steps", 1), ("mc_samples", 1), ("grid_points", 2)):
            object.__setattr__(self, name, checks.integer(name, getattr(self, name), minimum))
        weights = _triple("cost_weights", self.cost_weights, 4)
        for i, w in enumerate(weights):
            _positive(f"cost_weights[{i}]", w)
        object.__setattr__(self, "cost_weights", weights)
        object.__setattr__(
            self, "risk_tolerance", _positive("risk_tolerance", self.risk_tolerance, strict=False)
        )
        checks.text("severity", self.severity, SEVERITY_NAMES)
        object.__setattr__(self, "injury_beta0", _finite("injury_beta0", self.injury_beta0))
        # harm grows with delta-v
        object.__setattr__(self, "injury_beta1", _positive("injury_beta1", self.injury_beta1))
        v_lo, v_hi = self.uncertainty.velocity_bounds0
        if not v_lo <= self.object.speed <= v_hi:
            raise ValueError(
                f"object.speed {self.object.speed} m/s lies outside the speed truncation interval"
                f" uncertainty.velocity_bounds0 = {(v_lo, v_hi)}: the prediction's mean would fall outside"
                " its own support; widen velocity_bounds0"
            )
        if abs(self.path.curvature) > self.ego.omega_max / max(self.ego.v_ref, 1e-9):
            raise ValueError(
                f"path.curvature {self.path.curvature} needs a turn rate above ego.omega_max at"
                " v_ref: the path is not followable"
            )
        self._check_observable()

    def observation_reach(self) -> dict[str, tuple[float, float, str, str]]:
        """The largest magnitude each part of an observation can take within ``max_steps`` steps,
        with the bound of the observation Box, the unit and the fields that set it:
        ``{part: (reach, bound, unit, fields)}``.

        Worst cases, for either object motion: the ego moves at most ``max(|v_min|, |v_max|) dt``
        per step; the object at most ``V dt`` plus its one-step truncation half width per axis,
        with V its speed or, sampled, the edge of its one-step speed interval; the closest path
        point of a point at distance D from the goal lies within arc length pi D of it (its chord
        is at most 2 D), so the arc length and the position error are at most pi D. Actions may
        exceed the limits by :func:`risk_env.checks.slack`.
        """
        ego, obj, u, path = self.ego, self.object, self.uncertainty, self.path
        span = self.max_steps * self.dt
        # the env accepts actions beyond the limits by checks.slack (float32 rounding)
        v_lo, v_hi = ego.v_min - checks.slack(ego.v_min), ego.v_max + checks.slack(ego.v_max)
        ego_speed = max(abs(v_lo), abs(v_hi))
        ego_reach = span * ego_speed
        o_lo, o_hi = u.velocity_bounds0
        object_speed = max(abs(obj.speed), abs(o_lo - u.box_growth[2]), abs(o_hi + u.box_growth[2]))
        half = max(u.box_half_width0[0] + u.box_growth[0], u.box_half_width0[1] + u.box_growth[1])
        start, goal = ego.start, path.goal
        to_goal = math.hypot(start.x - goal.x, start.y - goal.y) + ego_reach
        o = obj.start
        moves = "max_steps, dt"
        return {
            "ego position": (
                max(abs(start.x), abs(start.y)) + ego_reach,
                POSITION_BOUND,
                "m",
                f"ego.start, ego.v_min, ego.v_max, {moves}",
            ),
            "arc length and path error": (
                math.pi * to_goal,
                POSITION_BOUND,
                "m",
                f"ego.start, path.goal, ego.v_min, ego.v_max, {moves}",
            ),
            "object position": (
                max(abs(o.x), abs(o.y)) + self.max_steps * (object_speed * self.dt + half),
                POSITION_BOUND,
                "m",
                "object.start, object.speed, uncertainty.velocity_bounds0, uncertainty.box_growth,"
                f" uncertainty.box_half_width0, {moves}",
            ),
            "ego speed": (ego_speed, RATE_BOUND, "m/s", "ego.v_min, ego.v_max"),
            "ego turn rate": (
                ego.omega_max + checks.slack(ego.omega_max),
                RATE_BOUND,
                "rad/s",
                "ego.omega_max",
            ),
            "speed error": (
                max(v_hi - ego.v_ref, ego.v_ref - v_lo),
                RATE_BOUND,
                "m/s",
                "ego.v_ref, ego.v_min, ego.v_max",
            ),
            "object speed": (
                object_speed,
                RATE_BOUND,
                "m/s",
                "object.speed, uncertainty.velocity_bounds0, uncertainty.box_growth[2]",
            ),
            "object turn rate": (abs(obj.turn_rate), RATE_BOUND, "rad/s", "object.turn_rate"),
        }

    def _check_observable(self) -> None:
        """Raise when an observation could leave the observation Box (see :meth:`observation_reach`)."""
        for part, (reach, bound, unit, names) in self.observation_reach().items():
            if not reach <= bound:
                raise ValueError(
                    f"the observation's {part} can reach {reach:.6g} {unit} in an episode of"
                    f" max_steps = {self.max_steps}, beyond the observation space's bound {bound:g}"
                    f" {unit}; change {names} (see risk_env.observation)"
                )

    @property
    def collision_distance(self) -> float:
        """r_e + r_o [m]: centre distance at or below which the discs touch."""
        return self.ego.radius + self.object.radius

    @classmethod
    def preset(cls, uncertainty: str = "low", **overrides: Any) -> Scenario:
        """The paper's scenario at an uncertainty level of Table I, with named overrides.

        Overrides are flat names (see :data:`OVERRIDES`), e.g. ``ego_start=(x, y, theta)``,
        ``object_speed=2.5``, ``v_ref=3.0``, ``severity="plastic"``, ``horizon=8``.
        """
        return cls(uncertainty=Uncertainty.preset(uncertainty)).replace(**overrides)

    def replace(self, **overrides: Any) -> Scenario:
        """A copy with flat-named fields replaced; unknown names raise with suggestions."""
        nested: dict[str, dict[str, Any]] = {}
        top: dict[str, Any] = {}
        for name, value in overrides.items():
            if name not in OVERRIDES:
                close = difflib.get_close_matches(name, OVERRIDES, n=3)
                hint = f"; did you mean {', '.join(close)}?" if close else ""
                raise TypeError(f"unknown scenario parameter {name!r}{hint} Valid names: {sorted(OVERRIDES)}")
            part, attr = OVERRIDES[name]
            if part is None:
                top[attr] = value
            else:
                nested.setdefault(part, {})[attr] = value
        for part, changes in nested.items():
            top[part] = dataclasses.replace(getattr(self, part), **changes)
        return dataclasses.replace(self, **top)


OVERRIDES: Mapping[str, tuple[str | None, str]] = {
    "ego_start": ("ego", "start"),
    "ego_radius": ("ego", "radius"),
    "ego_mass": ("ego", "mass"),
    "v_ref": ("ego", "v_ref"),
    "initial_input": ("ego", "initial_input"),
    "v_min": ("ego", "v_min"),
    "v_max": ("ego", "v_max"),
    "omega_max": ("ego", "omega_max"),
    "accel_max": ("ego", "accel_max"),
    "omega_rate_max": ("ego", "omega_rate_max"),
    "object_start": ("object", "start"),
    "object_speed": ("object", "speed"),
    "object_turn_rate": ("object", "turn_rate"),
    "object_radius": ("object", "radius"),
    "object_mass": ("object", "mass"),
    "sigma_growth": ("uncertainty", "sigma_growth"),
    "box_growth": ("uncertainty", "box_growth"),
    "sigma0": ("uncertainty", "sigma0"),
    "box_half_width0": ("uncertainty", "box_half_width0"),
    "velocity_bounds0": ("uncertainty", "velocity_bounds0"),
    "goal": ("path", "goal"),
    "curvature": ("path", "curvature"),
    "lambda_start": ("path", "lambda_start"),
    "dt": (None, "dt"),
    "horizon": (None, "horizon"),
    "cost_weights": (None, "cost_weights"),
    "risk_tolerance": (None, "risk_tolerance"),
    "severity": (None, "severity"),
    "injury_beta0": (None, "injury_beta0"),
    "injury_beta1": (None, "injury_beta1"),
    "max_steps": (None, "max_steps"),
    "mc_samples": (None, "mc_samples"),
    "grid_points": (None, "grid_points"),
}
"""Flat override names accepted by :meth:`Scenario.preset`, the env and the agents."""
