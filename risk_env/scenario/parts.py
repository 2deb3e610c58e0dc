"""The parts of a :class:`~risk_env.scenario.scenario.Scenario`, each a frozen dataclass with units: the
ego vehicle, the crossing objects, the prediction's uncertainty and the reference path.

Each part checks its own numbers on construction and names the field it rejects
(``ego.radius must be > 0, got -1.0``). :mod:`risk_env.scenario.scenario` re-exports them all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from risk_env import checks

UNCERTAINTY_PRESETS: tuple[str, ...] = ("low", "medium", "high")


def set_numbers(owner: Any, prefix: str, names: tuple[str, ...]) -> None:
    """Replace each field in ``names`` of the frozen ``owner`` by its value as a finite float."""
    for name in names:
        object.__setattr__(owner, name, checks.finite(f"{prefix}{name}", getattr(owner, name)))


@dataclass(frozen=True)
class Pose:
    r"""A planar configuration $y = (c_1, c_2, \theta)$."""

    x: float
    """c1 position [m]."""
    y: float
    """c2 position [m]."""
    theta: float
    """Heading [rad], counter-clockwise from the c1 axis."""

    def __post_init__(self) -> None:
        set_numbers(self, "Pose.", ("x", "y", "theta"))

    @classmethod
    def of(cls, value: Pose | tuple[float, float, float] | Any, name: str = "pose") -> Pose:
        """Build a pose from a ``(x, y, theta)`` sequence, naming ``name`` in errors."""
        if isinstance(value, Pose):
            return value
        return cls(*checks.finite_reals(name, value, 3))

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
    """Disc radius $r_e$ [m]."""
    mass: float = 1000.0
    """Mass $m_e$ [kg]."""
    v_ref: float = 4.0
    """Reference speed $v_{ref}$ [m/s] (the appendix says 3, the velocity figure converges to 4)."""
    initial_input: tuple[float, float] = (0.0, 0.0)
    """Input ``(v [m/s], omega [rad/s])`` applied before the first step."""
    v_min: float = -4.0
    """Lowest speed [m/s] (negative: reversing)."""
    v_max: float = 8.0
    """Highest speed [m/s]."""
    omega_max: float = 0.8
    """Largest turn-rate magnitude [rad/s]."""
    accel_max: float = 3.0
    """Largest speed change per second [m/s^2] (a rate limit on $v$)."""
    omega_rate_max: float = 1.6
    r"""Largest turn-rate change per second [rad/s^2] (a rate limit on $\omega$)."""
    curvature_max: float = math.inf
    r"""Largest curvature of its course $\kappa_{max}$ [1/m]: $|\omega| \le \kappa_{max} v$, so that it
    turns only while it moves, as a car does (inf: the paper's unicycle, which turns standing)."""
    discs: int = 1
    """Collision discs of radius ``radius`` along the heading (1: the paper's single disc)."""
    length: float = 0.0
    """Body length [m] the discs cover: their centres lie at the middles of ``discs`` equal pieces
    of it, centred on the pose (no effect with one disc)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", Pose.of(self.start, "ego.start"))
        object.__setattr__(
            self, "initial_input", checks.finite_reals("ego.initial_input", self.initial_input, 2)
        )
        set_numbers(self, "ego.", _EGO_NUMBERS)
        checks.positive("ego.radius", self.radius)
        checks.positive("ego.mass", self.mass)
        checks.positive("ego.v_ref", self.v_ref, strict=False)
        checks.positive("ego.v_max", self.v_max)
        if not self.v_min < self.v_max:
            raise ValueError(f"ego.v_min ({self.v_min}) must be below ego.v_max ({self.v_max})")
        if not self.v_min <= self.v_ref <= self.v_max:
            raise ValueError(
                f"ego.v_ref ({self.v_ref}) must lie in [v_min, v_max] = [{self.v_min}, {self.v_max}]"
            )
        checks.positive("ego.omega_max", self.omega_max)
        checks.positive("ego.accel_max", self.accel_max)
        checks.positive("ego.omega_rate_max", self.omega_rate_max)
        kappa = checks.real("ego.curvature_max", self.curvature_max)
        if not kappa > 0:  # NaN too
            raise ValueError(f"ego.curvature_max must be > 0 [1/m] (inf: none), got {self.curvature_max!r}")
        object.__setattr__(self, "curvature_max", kappa)
        if math.isfinite(self.curvature_max) and self.v_min < 0:
            raise ValueError(
                f"ego.curvature_max ({self.curvature_max}) needs ego.v_min >= 0, got {self.v_min}: a"
                " reversing ego's |omega| <= kappa |v| is not a pair of linear rows"
            )
        check_body(self, "ego")
        v0, w0 = self.initial_input
        if not (self.v_min <= v0 <= self.v_max and abs(w0) <= self.omega_max):
            raise ValueError(f"ego.initial_input {self.initial_input} lies outside the input limits")

    @property
    def disc_offsets(self) -> tuple[float, ...]:
        """Offsets [m] of the disc centres along the heading (:func:`disc_offsets`)."""
        return disc_offsets(self.discs, self.length)


def disc_offsets(discs: int, length: float) -> tuple[float, ...]:
    """Offsets [m] along the heading of ``discs`` disc centres covering a body of ``length`` [m]:
    the middles of equal pieces, ``(0.0,)`` for one disc."""
    if discs == 1:
        return (0.0,)
    return tuple(length * ((i + 0.5) / discs - 0.5) for i in range(discs))


def check_body(owner: Any, prefix: str) -> None:
    """Check (and store) ``owner``'s ``discs`` (an integer >= 1) and ``length`` (finite, >= 0 [m],
    > 0 with several discs); errors name ``prefix.field``."""
    object.__setattr__(owner, "discs", checks.integer(f"{prefix}.discs", owner.discs, minimum=1))
    set_numbers(owner, f"{prefix}.", ("length",))
    checks.positive(f"{prefix}.length", owner.length, strict=owner.discs > 1)


@dataclass(frozen=True)
class Uncertainty:
    r"""How an object's prediction spreads over the horizon (paper Sec. VI-C, Table I).

    At prediction step $n$ the object's position and speed follow independent truncated Gaussians
    centred on the predicted mean $\mu_n$, with standard deviations $\Sigma_0 + n Q$ (``sigma0``,
    ``sigma_growth``) and a truncation box $\mu_n \pm (b_0 + n \Delta)$ (``box_half_width0``,
    ``box_growth``); the speed is truncated to $[v_{min} - n \Delta_v,\ v_{max} + n \Delta_v]$
    (``velocity_bounds0``).
    """

    sigma_growth: tuple[float, float, float] = (0.1, 0.1, 0.1)
    """$Q$: added standard deviation per step for (c1 [m], c2 [m], v [m/s])."""
    box_growth: tuple[float, float, float] = (1.0, 1.0, 1.0)
    r"""$\Delta$: truncation growth per step and side for (c1 [m], c2 [m], v [m/s])."""
    sigma0: tuple[float, float, float] = (0.0, 0.0, 0.0)
    r"""$\Sigma_0$: standard deviations at the measurement (c1 [m], c2 [m], v [m/s])."""
    box_half_width0: tuple[float, float] = (0.0, 0.0)
    """Half widths of the position truncation box at the measurement (c1 [m], c2 [m])."""
    velocity_bounds0: tuple[float, float] = (-5.0, 5.0)
    """Speed truncation interval at the measurement ``(v_min, v_max)`` [m/s]."""

    def __post_init__(self) -> None:
        check_uncertainty(self, "uncertainty")

    @classmethod
    def preset(cls, name: str) -> Uncertainty:
        """The paper's Table I: ``"low"``, ``"medium"`` or ``"high"``."""
        table = {"low": (0.1, 1.0), "medium": (0.8, 2.0), "high": (1.5, 3.0)}
        checks.text("uncertainty preset", name, UNCERTAINTY_PRESETS)
        q, delta = table[name]
        return cls(sigma_growth=(q, q, q), box_growth=(delta, delta, delta))


UNCERTAINTY_FIELDS: dict[str, int] = {
    "sigma_growth": 3,
    "box_growth": 3,
    "sigma0": 3,
    "box_half_width0": 2,
    "velocity_bounds0": 2,
}
"""The fields of :class:`Uncertainty` and their lengths."""


def check_uncertainty(u: Uncertainty, prefix: str) -> None:
    """Check (and store as float tuples) the fields of ``u``; errors name ``prefix.field``."""
    for name, length in UNCERTAINTY_FIELDS.items():
        value = checks.finite_reals(f"{prefix}.{name}", getattr(u, name), length)
        if name != "velocity_bounds0":
            for i, v in enumerate(value):
                checks.positive(f"{prefix}.{name}[{i}]", v, strict=False)
        object.__setattr__(u, name, value)
    lo, hi = u.velocity_bounds0
    if lo > hi:
        raise ValueError(f"{prefix}.velocity_bounds0 must be (low, high), got {(lo, hi)}")


@dataclass(frozen=True)
class CrossingObject:
    """A road user crossing the path: a unicycle with constant inputs, a disc of its own radius
    and mass, and optionally its own prediction spread."""

    start: Pose = Pose(5.0, -5.0, math.pi / 2)
    """Initial configuration ``(c1 [m], c2 [m], theta [rad])``."""
    speed: float = 3.0
    """Constant speed input $v_o$ [m/s]."""
    turn_rate: float = 1e-4
    r"""Constant turn-rate input $\omega_o$ [rad/s]."""
    radius: float = 1.5
    """Disc radius $r_o$ [m]."""
    mass: float = 1000.0
    """Mass $m_o$ [kg]."""
    uncertainty: Uncertainty | None = None
    """Its own prediction spread; None (default): the scenario's ``uncertainty``."""
    discs: int = 1
    """Collision discs of radius ``radius`` along its heading (1: the paper's single disc)."""
    length: float = 0.0
    """Body length [m] the discs cover: their centres lie at the middles of ``discs`` equal pieces
    of it, centred on the pose (no effect with one disc)."""

    def __post_init__(self) -> None:
        check_object(self, "object")

    @property
    def disc_offsets(self) -> tuple[float, ...]:
        """Offsets [m] of the disc centres along the heading (:func:`disc_offsets`)."""
        return disc_offsets(self.discs, self.length)


def check_object(obj: CrossingObject, prefix: str) -> None:
    """Check (and store as floats) the fields of ``obj``; errors name ``prefix.field``, e.g.
    ``objects[1].speed``."""
    object.__setattr__(obj, "start", Pose.of(obj.start, f"{prefix}.start"))
    set_numbers(obj, f"{prefix}.", ("speed", "turn_rate", "radius", "mass"))
    checks.positive(f"{prefix}.radius", obj.radius)
    checks.positive(f"{prefix}.mass", obj.mass)
    check_body(obj, prefix)
    if obj.uncertainty is not None and not isinstance(obj.uncertainty, Uncertainty):
        raise TypeError(
            f"{prefix}.uncertainty must be an Uncertainty, a preset name or None, got"
            f" {checks.describe(obj.uncertainty)}"
        )


@dataclass(frozen=True)
class ReferencePath:
    r"""A constant-curvature arc ending at the goal pose (paper appendix).

    $y_P(\lambda)$ for arc length $\lambda \le 0$ ends at ``goal`` for $\lambda = 0$; with the goal
    heading 0: $c_1 = g_x + \sin(\kappa \lambda)/\kappa$, $c_2 = g_y + (1 - \cos(\kappa \lambda))/\kappa$.
    """

    goal: Pose = Pose(65.0, 5.0, 0.0)
    r"""Goal configuration $y_P(\lambda_g)$ [m, m, rad]."""
    curvature: float = 0.003
    r"""$\kappa$ [1/m]; positive turns left, 0 is a straight line."""
    lambda_start: float = -95.0
    r"""$\lambda_0$ [m]: the arc length of the path's first point; the goal is at $\lambda_g = 0$."""
    corridor: float = math.inf
    """Half width [m] of the corridor around the (continued) arc that an MPC's planned ego centre
    keeps within at n = 1..N, measured across the arc (a lane: its half width less the ego's);
    ``inf``: none (the paper's)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "goal", Pose.of(self.goal, "path.goal"))
        set_numbers(self, "path.", ("curvature", "lambda_start"))
        corridor = checks.real("path.corridor", self.corridor)
        if not corridor > 0:
            raise ValueError(f"path.corridor must be > 0 [m] (inf: none), got {self.corridor!r}")
        object.__setattr__(self, "corridor", float(corridor))
        if self.lambda_start >= 0:
            raise ValueError(f"path.lambda_start must be < 0 (goal at 0), got {self.lambda_start}")
        if abs(self.curvature * self.lambda_start) >= math.pi:
            raise ValueError(
                "path.curvature * path.lambda_start must stay within (-pi, pi) so the arc does not"
                f" close on itself, got {self.curvature * self.lambda_start:.3f}"
            )

    @property
    def lambda_goal(self) -> float:
        r"""$\lambda_g$ [m]: always 0, the goal's arc length."""
        return 0.0
