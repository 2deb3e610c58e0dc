"""Seeded variations of a scenario, so that a learned policy cannot memorise one episode.

With ``randomize=True`` the env (and its vectorised form) starts each episode from
:func:`vary`: the path's curvature, the ego's start relative to the path, and each object's
start and speed are drawn uniformly around the base scenario's values; with
``Variations(object_count=True)`` also how many of the objects cross (the first m of M, m uniform
on 1..M). Everything else (the uncertainty, the limits, the goal, the sample time, the objects'
turn rates, radii and masses) stays the base scenario's.

Draw order: 4 uniforms for the path and the ego, 4 per object in order (the paper's one object
first: so a single-object scenario draws exactly the 8 of :data:`DRAWS`, as it always has), then
one for the count when it is drawn (:func:`draw_count`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from risk_env import checks
from risk_env.models.ops import MATH, Ops
from risk_env.models.path import PathBatch, point, project
from risk_env.scenario.scenario import Scenario


@dataclass(frozen=True)
class Variations:
    """Half ranges of the uniform draws around the base scenario's values (0 switches one off)."""

    curvature: float = 0.004
    r"""$\kappa$ [1/m]; clipped so the path stays followable at $v_{ref}$ and does not close on itself."""
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
    object_count: bool = False
    """Also draw how many of the objects cross: the first m of the scenario's M, m uniform on
    1..M (the others are absent for the episode: their observation slots flagged 0)."""

    def __post_init__(self) -> None:
        checks.flag("Variations.object_count", self.object_count)
        for f in dataclasses.fields(self):
            if f.name == "object_count":
                continue
            value = checks.real(f"Variations.{f.name}", getattr(self, f.name))
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"Variations.{f.name} must be finite and >= 0, got {value!r}")
            object.__setattr__(self, f.name, value)


DRAWS = 8
"""Uniform numbers one variation of a single-object scenario takes from the generator."""
OBJECT_DRAWS = 4
"""Uniform numbers per object (c1, c2, theta, speed)."""


def draw_count(base: Scenario, variations: Variations = Variations()) -> int:
    """Uniform numbers one variation of ``base`` takes: 4, 4 per object, 1 for the count if drawn."""
    return 4 + OBJECT_DRAWS * len(base.objects) + int(variations.object_count)


class Start(NamedTuple):
    """What :func:`draw` draws: floats for one episode, arrays ``(B,)`` for a batch of them."""

    curvature: Any
    r"""$\kappa$ of the path [1/m]."""
    ego: tuple[Any, Any, Any]
    """The ego's start ``(c1 [m], c2 [m], theta [rad])``."""
    objects: tuple[tuple[Any, Any, Any, Any], ...]
    """Each object's start and speed ``(c1 [m], c2 [m], theta [rad], v [m/s])``, in order."""
    count: Any
    """How many objects cross (the first ones): an int (arrays ``(B,)``), or None: all."""


def draw(base: Scenario, u: Any, variations: Variations = Variations(), ops: Ops = MATH) -> Start:
    """The start drawn around ``base`` from uniforms ``u`` on [-1, 1): :func:`draw_count` floats
    (:data:`~risk_env.models.ops.MATH`), or ``(draw_count, B)`` arrays for B episodes
    (:data:`~risk_env.models.ops.NUMPY`)."""
    ego, path = base.ego, base.path
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
    objects = []
    for i, (obj, un) in enumerate(zip(base.objects, base.uncertainties, strict=True)):
        k = 4 + OBJECT_DRAWS * i
        s = obj.start
        v_lo, v_hi = un.velocity_bounds0
        objects.append(
            (
                s.x + variations.object_position * u[k],
                s.y + variations.object_position * u[k + 1],
                s.theta + variations.object_heading * u[k + 2],
                ops.clip(obj.speed + variations.object_speed * u[k + 3], v_lo, v_hi),
            )
        )
    count = None
    if variations.object_count:  # m = 1 + floor(M (u + 1) / 2), at most M
        m = len(base.objects)
        count = ops.minimum(ops.floor(0.5 * (u[4 + OBJECT_DRAWS * m] + 1.0) * m), m - 1) + 1
        count = int(count) if ops is MATH else count.astype(np.int64)
    return Start(curvature, ego_start, tuple(objects), count)


def vary(base: Scenario, rng: np.random.Generator, variations: Variations = Variations()) -> Scenario:
    """A scenario drawn around ``base`` with ``rng`` (exactly :func:`draw_count` uniforms on [-1, 1))."""
    start = draw(base, rng.uniform(-1.0, 1.0, size=draw_count(base, variations)).tolist(), variations, MATH)
    objects = tuple(
        dataclasses.replace(obj, start=drawn[:3], speed=drawn[3])
        for obj, drawn in zip(base.objects, start.objects, strict=True)
    )
    return base.replace(
        curvature=start.curvature,
        ego_start=start.ego,
        objects=objects if start.count is None else objects[: start.count],
    )
