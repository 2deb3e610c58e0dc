"""Named scenes: which road users cross the path, as ``objects=`` specifications.

A scene fixes the objects of a :class:`~risk_env.scenario.scenario.Scenario` and nothing else (the ego,
the path, the uncertainty level and every other number stay the scenario's):

>>> from risk_env import Scenario
>>> s = Scenario.preset("medium", scene="two_crossing")
>>> [o.start.theta > 0 for o in s.objects]  # the first heads north, the second south
[True, False]

or ``gym.make("RiskCrossing-v0", scene="two_crossing")``. The scenes:

- ``"paper"``: the paper's object, from (5, -5) heading north at 3 m/s, crossing the path near
  c1 = 5 m;
- ``"two_crossing"``: the paper's object, and a second road user crossing from the other side:
  north of the path, heading south at 2.5 m/s, crossing near c1 = 25 m, where the ego arrives a
  few seconds after passing the first;
- ``"four_crossing"``: the two of ``"two_crossing"`` and two more crossing further on, one from
  each side: a scene for throughput and multi-object tests.

Each object is a dict of :class:`~risk_env.scenario.scenario.CrossingObject` fields (``start``,
``speed``, ``turn_rate``, optionally ``radius``, ``mass`` and uncertainty keys), exactly what
``objects=[...]`` takes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from risk_env import checks

PAPER_OBJECT: Mapping[str, Any] = {"start": (5.0, -5.0, math.pi / 2), "speed": 3.0, "turn_rate": 1e-4}
"""The paper's crossing object (its appendix): from (5, -5) heading north at 3 m/s."""

SCENES: Mapping[str, tuple[Mapping[str, Any], ...]] = {
    "paper": (PAPER_OBJECT,),
    "two_crossing": (
        PAPER_OBJECT,
        {"start": (25.0, 38.0, -math.pi / 2), "speed": 2.5, "turn_rate": 1e-4},
    ),
    "four_crossing": (
        PAPER_OBJECT,
        {"start": (25.0, 38.0, -math.pi / 2), "speed": 2.5, "turn_rate": 1e-4},
        {"start": (45.0, -15.0, math.pi / 2), "speed": 2.0, "turn_rate": 1e-4},
        {"start": (12.0, 28.0, -math.pi / 2), "speed": 3.5, "turn_rate": -1e-4},
    ),
}
"""Scene name -> its objects (``objects=`` specifications, in order)."""
SCENE_NAMES: tuple[str, ...] = tuple(SCENES)


def scene_objects(name: str) -> tuple[Mapping[str, Any], ...]:
    """The object specifications of scene ``name`` (one of :data:`SCENE_NAMES`)."""
    return SCENES[checks.text("scene", name, SCENE_NAMES)]
