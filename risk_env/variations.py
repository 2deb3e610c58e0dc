"""Seeded variations of a scenario, so that a learned policy cannot memorise one episode.

With ``randomize=True`` the env (and its vectorised form) starts each episode from
:func:`vary`: the path's curvature, the ego's start relative to the path, and the object's
start and speed are drawn uniformly around the base scenario's values. Everything else (the
uncertainty, the limits, the goal, the sample time) stays the base scenario's.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from risk_env import checks
from risk_env.ops import MATH, Ops
from risk_env.path import PathBatch, point, project
from risk_env.scenario import Scenario


@dataclass(frozen=True)
class Variations:
    """Half ranges of the uniform draws around the base scenario's values (0 switches one off)."""

    curvature: float = 0.004
    """kappa [1/m]; clipped so the path stays followable at v_ref and does not close on itself."""
    ego_shift: float = 5.0
    """The ego's start moves along the path by up to this much [m]."""
    ego_offset: float = 1.5
    """... and sideways off the path by up to this much [m], added to the base start's offset."""
    ego_heading: float = 0.2
    """... and turns by up to this much [rad] relative to the path."""
    object_position: float = 4.0
    """The object's start moves by up to this much [m] along each axis."""
    object_heading: float = 0.3
    """The object's start heading turns by up to this much [rad]."""
    object_speed: float = 1.5
    """The object's speed changes by up to this much [m/s], clipped to its truncation interval."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = checks.real(f"Variations.{f.name}", getattr(self, f.name))
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"Variations.{f.name} must be finite and >= 0, got {value!r}")
            object.__setattr__(self, f.name, value)


DRAWS = 8
"""Uniform numbers one variation takes from the generator."""


class Start(NamedTuple):
    """What :func:`vary` draws: floats for one episode, arrays ``(B,)`` for a batch of them."""

    curvature: Any
    """kappa of the path [1/m]."""
    ego: tuple[Any, Any, Any]
    """The ego's start ``(c1 [m], c2 [m], theta [rad])``."""
    object: tuple[Any, Any, Any]
    """The object's start ``(c1 [m], c2 [m], theta [rad])``."""
    object_speed: Any
    """The object's speed [m/s]."""


def draw(base: Scenario, u: Any, variations: Variations = Variations(), ops: Ops = MATH) -> Start:
    """The start drawn around ``base`` from uniforms ``u`` on [-1, 1): :data:`DRAWS` floats
    (:data:`~risk_env.ops.MATH`), or ``(DRAWS, B)`` arrays for B episodes (:data:`~risk_env.ops.NUMPY`)."""
    ego, obj, path = base.ego, base.object, base.path
    # the base ego start in path coordinates: arc length, lateral offset, heading offset
    lam0 = project(path, ego.start.x, ego.start.y, MATH)
    px, py, pth = point(path, lam0, MATH)
    offset0 = -math.sin(pth) * (ego.start.x - px) + math.cos(pth) * (ego.start.y - py)
    heading0 = ego.start.theta - pth

    limit = min(0.9 * ego.omega_max / max(ego.v_ref, 1e-9), 0.9 * math.pi / abs(path.lambda_start))
    curvature = ops.clip(path.curvature + variations.curvature * u[0], -limit, limit)
    lam = lam0 + variations.ego_shift * u[1]
    px, py, pth = point(PathBatch(curvature, path.goal), lam, ops)
    offset = offset0 + variations.ego_offset * u[2]
    ego_start = (
        px - ops.sin(pth) * offset,
        py + ops.cos(pth) * offset,
        pth + heading0 + variations.ego_heading * u[3],
    )
    s = obj.start
    object_start = (
        s.x + variations.object_position * u[4],
        s.y + variations.object_position * u[5],
        s.theta + variations.object_heading * u[6],
    )
    v_lo, v_hi = base.uncertainty.velocity_bounds0
    speed = ops.clip(obj.speed + variations.object_speed * u[7], v_lo, v_hi)
    return Start(curvature, ego_start, object_start, speed)


def vary(base: Scenario, rng: np.random.Generator, variations: Variations = Variations()) -> Scenario:
    """A scenario drawn around ``base`` with ``rng`` (exactly :data:`DRAWS` uniforms on [-1, 1))."""
    start = draw(base, rng.uniform(-1.0, 1.0, size=DRAWS).tolist(), variations, MATH)
    return base.replace(
        curvature=start.curvature,
        ego_start=start.ego,
        object_start=start.object,
        object_speed=start.object_speed,
    )
