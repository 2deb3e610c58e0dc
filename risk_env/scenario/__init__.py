"""The scenario: one frozen dataclass tree with every number of the case study.

- :mod:`~risk_env.scenario.scenario`: :class:`Scenario`, its presets and overrides;
- :mod:`~risk_env.scenario.parts`: its parts (ego, objects, uncertainty, path), each checking itself;
- :mod:`~risk_env.scenario.scenes`: the named multi-object scenes;
- :mod:`~risk_env.scenario.reach`: how far a scenario's observations reach, against the Box.
"""

from risk_env.scenario.parts import (
    UNCERTAINTY_PRESETS,
    CrossingObject,
    Ego,
    Pose,
    ReferencePath,
    Uncertainty,
)
from risk_env.scenario.scenario import (
    OBJECT_KEYS,
    OVERRIDES,
    RISK_TOLERANCES,
    SEVERITY_NAMES,
    Scenario,
    make_objects,
)
from risk_env.scenario.scenes import SCENE_NAMES

__all__ = [
    "OBJECT_KEYS",
    "OVERRIDES",
    "RISK_TOLERANCES",
    "SCENE_NAMES",
    "SEVERITY_NAMES",
    "UNCERTAINTY_PRESETS",
    "CrossingObject",
    "Ego",
    "Pose",
    "ReferencePath",
    "Scenario",
    "Uncertainty",
    "make_objects",
]
