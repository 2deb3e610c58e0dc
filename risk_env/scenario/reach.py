"""How far a scenario's observations can reach within an episode, against the observation Box.

The observation Box is fixed (:mod:`risk_env.observation`); :class:`~risk_env.scenario.scenario.Scenario`
rejects, naming the fields, any scenario whose observations could leave it, for any actions and
with the objects moving either way (``object_motion="paper"`` or ``"sampled"``). Every object is
checked with its own start, speed, turn rate and uncertainty.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

from risk_env import checks
from risk_env.observation import POSITION_BOUND, RATE_BOUND
from risk_env.scenario.parts import CrossingObject, Ego, ReferencePath, Uncertainty


class Scenario(Protocol):
    """What the reach of a scenario depends on (a :class:`~risk_env.scenario.scenario.Scenario`
    has it all): its parts, the number of steps and the sample time."""

    @property
    def ego(self) -> Ego: ...
    @property
    def path(self) -> ReferencePath: ...
    @property
    def objects(self) -> Sequence[CrossingObject]: ...
    @property
    def uncertainties(self) -> Sequence[Uncertainty]: ...
    @property
    def max_steps(self) -> int: ...
    @property
    def dt(self) -> float: ...


Reach = dict[str, tuple[float, float, str, str]]
"""``{part: (reach, bound, unit, fields)}``."""


def object_label(index: int, count: int) -> str:
    """How errors name object ``index`` of ``count``: ``object`` alone, else ``objects[i]``."""
    return "object" if count == 1 else f"objects[{index}]"


def observation_reach(scenario: Scenario) -> Reach:
    r"""The largest magnitude each part of an observation can take within ``max_steps`` steps,
    with the bound of the observation Box, the unit and the fields that set it:
    ``{part: (reach, bound, unit, fields)}``; the object parts once per object (``"object
    position"`` for a single object, ``"objects[1] position"`` for the second of several).

    Worst cases, for either object motion: the ego moves at most $\max(|v_{min}|, |v_{max}|)\, dt$
    per step; an object at most $V dt$ plus its one-step truncation half width per axis,
    with $V$ its speed or, sampled, the edge of its one-step speed interval; the closest path
    point of a point at distance $D$ from the goal lies within arc length $\pi D$ of it (its chord
    is at most $2 D$), so the arc length and the position error are at most $\pi D$. Actions may
    exceed the limits by :func:`risk_env.checks.slack`.
    """
    s = scenario
    ego, path = s.ego, s.path
    span = s.max_steps * s.dt
    # the env accepts actions beyond the limits by checks.slack (float32 rounding)
    v_lo, v_hi = ego.v_min - checks.slack(ego.v_min), ego.v_max + checks.slack(ego.v_max)
    ego_speed = max(abs(v_lo), abs(v_hi))
    ego_reach = span * ego_speed
    start, goal = ego.start, path.goal
    to_goal = math.hypot(start.x - goal.x, start.y - goal.y) + ego_reach
    moves = "max_steps, dt"
    out: Reach = {
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
    }
    count = len(s.objects)
    for i, (obj, u) in enumerate(zip(s.objects, s.uncertainties, strict=True)):
        name = object_label(i, count)
        un = f"{name}.uncertainty" if obj.uncertainty is not None else "uncertainty"
        o_lo, o_hi = u.velocity_bounds0
        speed = max(abs(obj.speed), abs(o_lo - u.box_growth[2]), abs(o_hi + u.box_growth[2]))
        half = max(u.box_half_width0[0] + u.box_growth[0], u.box_half_width0[1] + u.box_growth[1])
        o = obj.start
        out[f"{name} position"] = (
            max(abs(o.x), abs(o.y)) + s.max_steps * (speed * s.dt + half),
            POSITION_BOUND,
            "m",
            f"{name}.start, {name}.speed, {un}.velocity_bounds0, {un}.box_growth,"
            f" {un}.box_half_width0, {moves}",
        )
        out[f"{name} speed"] = (
            speed,
            RATE_BOUND,
            "m/s",
            f"{name}.speed, {un}.velocity_bounds0, {un}.box_growth[2]",
        )
        out[f"{name} turn rate"] = (abs(obj.turn_rate), RATE_BOUND, "rad/s", f"{name}.turn_rate")
    return out


def check_observable(scenario: Scenario) -> None:
    """Raise when an observation could leave the observation Box (see :func:`observation_reach`)."""
    for part, (reach, bound, unit, names) in observation_reach(scenario).items():
        if not reach <= bound:
            raise ValueError(
                f"the observation's {part} can reach {reach:.6g} {unit} in an episode of"
                f" max_steps = {scenario.max_steps}, beyond the observation space's bound {bound:g}"
                f" {unit}; change {names} (see risk_env.observation)"
            )
