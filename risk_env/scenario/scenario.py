"""The crossing-object scenario of the paper as one frozen dataclass tree.

Every number of the case study lives here, with its unit. The env, the agents and the benchmarks
all take a :class:`Scenario`; nothing else holds scenario constants. Its parts (:class:`Ego`,
:class:`CrossingObject`, :class:`Uncertainty`, :class:`ReferencePath`, :class:`Pose`) are defined
in :mod:`risk_env.scenario.parts` and re-exported here.

>>> s = Scenario.preset("medium", v_ref=3.0, risk_tolerance=500.0)
>>> s.uncertainty.sigma_growth
(0.8, 0.8, 0.8)

Several road users: ``Scenario.preset("low", scene="two_crossing")`` (:mod:`risk_env.scenario.scenes`) or
``objects=[{"start": (c1, c2, theta), "speed": v, "turn_rate": omega}, ...]``:

>>> s = Scenario.preset("low", objects=[{}, {"start": (25.0, 32.0, -1.57), "speed": 2.5}])
>>> len(s.objects), s.object.speed, s.objects[1].speed
(2, 3.0, 2.5)
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from risk_env import checks
from risk_env.scenario.parts import (
    UNCERTAINTY_FIELDS,
    UNCERTAINTY_PRESETS,
    CrossingObject,
    Ego,
    ReferencePath,
    Uncertainty,
    check_object,
    check_uncertainty,
)
from risk_env.scenario.parts import Pose as Pose  # re-exported, as the parts above
from risk_env.scenario.reach import Reach, check_observable, object_label, observation_reach
from risk_env.scenario.scenes import SCENE_NAMES as SCENE_NAMES
from risk_env.scenario.scenes import scene_objects

SeverityName = Literal["paper", "plastic", "probability", "injury"]
SEVERITY_NAMES: tuple[str, ...] = ("paper", "plastic", "probability", "injury")
RISK_TOLERANCES: tuple[float, ...] = (0.0, 500.0, 1000.0, 1500.0, 2000.0, 2500.0)
r"""The paper's risk tolerances $\epsilon$ [J] (Table II)."""
RISK_BOUNDS: Mapping[str, tuple[float, str]] = {
    "paper": (math.inf, "J"),
    "plastic": (math.inf, "J"),
    "probability": (1.0, "probability"),
    "injury": (2.0, "injuries"),
}
"""Per severity, the largest per-step risk and its unit (the models' ``upper_bound`` and ``unit``,
:mod:`risk_env.severity`): a tolerance above the bound is a value in another unit."""
MAX_MASS = 1e30
"""The largest mass [kg] of the ego or an object (about the Sun's): beyond it a mass is a mistake,
and the severities' products of masses and squared speeds near float overflow (1e308 kg made the
risk inf and the reward NaN)."""
OBJECT_KEYS: tuple[str, ...] = (
    *(f.name for f in dataclasses.fields(CrossingObject)),
    *UNCERTAINTY_FIELDS,
)
"""Keys of an object given as a dict in ``objects=[...]``: the :class:`CrossingObject` fields
(``"uncertainty"``: an :class:`Uncertainty`, a preset name or None) and the :class:`Uncertainty`
fields, which give the object its own spread, starting from its ``"uncertainty"`` or else the
scenario's."""


@dataclass(frozen=True)
class Scenario:
    """Everything that defines one crossing case study: the ego, the objects that cross its path
    (the paper's one by default), their uncertainty, the path and the settings.

    Build one with :meth:`preset` (the paper's numbers, a scene, named overrides) or directly.
    """

    ego: Ego = field(default_factory=Ego)
    objects: tuple[CrossingObject, ...] = (CrossingObject(),)
    """The road users crossing the path, in order (at least one); a sequence of
    :class:`CrossingObject` or dicts of their fields (:data:`OBJECT_KEYS`). :attr:`object` is the
    first."""
    uncertainty: Uncertainty = field(default_factory=Uncertainty)
    """The prediction spread of every object without its own."""
    path: ReferencePath = field(default_factory=ReferencePath)
    dt: float = 0.5
    """Sample time T [s]."""
    horizon: int = 6
    """Prediction horizon N [steps]."""
    cost_weights: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    """Diagonal of $W$ for the stage cost $e^T W e$ over (c1 [m], c2 [m], theta [rad], v [m/s])."""
    risk_tolerance: float = 0.0
    r"""$\epsilon$: the bound on the risk [units of the severity: J for the paper's]."""
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
        for name, cls in (("ego", Ego), ("uncertainty", Uncertainty), ("path", ReferencePath)):
            value = getattr(self, name)
            if not isinstance(value, cls):
                raise TypeError(f"scenario.{name} must be a {cls.__name__}, got {checks.describe(value)}")
        object.__setattr__(self, "objects", make_objects(self.objects, self.uncertainty))
        object.__setattr__(self, "dt", checks.positive("dt", self.dt))
        for name, minimum in (("horizon", 1), ("max_steps", 1), ("mc_samples", 1), ("grid_points", 2)):
            object.__setattr__(self, name, checks.integer(name, getattr(self, name), minimum))
        weights = checks.finite_reals("cost_weights", self.cost_weights, 4)
        for i, w in enumerate(weights):
            checks.positive(f"cost_weights[{i}]", w)
        object.__setattr__(self, "cost_weights", weights)
        object.__setattr__(
            self, "risk_tolerance", checks.positive("risk_tolerance", self.risk_tolerance, strict=False)
        )
        checks.text("severity", self.severity, SEVERITY_NAMES)
        bound, unit = RISK_BOUNDS[self.severity]
        checks.within_severity("risk_tolerance", self.risk_tolerance, self.severity, bound, unit)
        masses = [("ego.mass", self.ego.mass)]
        masses += [(f"{object_label(i, len(self.objects))}.mass", o.mass) for i, o in enumerate(self.objects)]
        for name, mass in masses:
            if mass > MAX_MASS:
                raise ValueError(f"{name} must be at most {MAX_MASS:g} kg, got {mass:g} kg")
        object.__setattr__(self, "injury_beta0", checks.finite("injury_beta0", self.injury_beta0))
        # harm grows with delta-v
        object.__setattr__(self, "injury_beta1", checks.positive("injury_beta1", self.injury_beta1))
        for i, (obj, u) in enumerate(zip(self.objects, self.uncertainties, strict=True)):
            v_lo, v_hi = u.velocity_bounds0
            if not v_lo <= obj.speed <= v_hi:
                name = object_label(i, len(self.objects))
                bounds = "uncertainty" if obj.uncertainty is None else f"{name}.uncertainty"
                raise ValueError(
                    f"{name}.speed {obj.speed} m/s lies outside the speed truncation interval"
                    f" {bounds}.velocity_bounds0 = {(v_lo, v_hi)}: the prediction's mean would fall"
                    " outside its own support; widen velocity_bounds0"
                )
        if abs(self.path.curvature) > self.ego.omega_max / max(self.ego.v_ref, 1e-9):
            raise ValueError(
                f"path.curvature {self.path.curvature} needs a turn rate above ego.omega_max at"
                " v_ref: the path is not followable"
            )
        check_observable(self)

    # ---------------------------------------------------------------- the objects
    @property
    def object(self) -> CrossingObject:
        """The first object (the paper's only one)."""
        return self.objects[0]

    @property
    def uncertainties(self) -> tuple[Uncertainty, ...]:
        """Each object's prediction spread: its own, else the scenario's :attr:`uncertainty`."""
        u = self.uncertainty
        return tuple(u if o.uncertainty is None else o.uncertainty for o in self.objects)

    @property
    def collision_distance(self) -> float:
        """$r_e + r_o$ [m] of the first object: the centre distance at or below which the discs touch."""
        return self.ego.radius + self.objects[0].radius

    @property
    def collision_distances(self) -> tuple[float, ...]:
        """$r_e + r_{o,i}$ [m] of each object $i$."""
        return tuple(self.ego.radius + o.radius for o in self.objects)

    def for_object(self, index: int) -> Scenario:
        """The single-object scenario of object ``index``: that object alone (without its own
        uncertainty), whose spread becomes the scenario's :attr:`uncertainty`; the rest as is.
        Everything single-object (a risk estimator, :func:`risk_env.predict`, the severity's
        masses, ``collision_distance``) then describes that object."""
        count = len(self.objects)
        index = checks.integer("object index", index, minimum=0)
        if index >= count:
            raise ValueError(f"object index {index} is out of range: the scenario has {count} object(s)")
        obj = self.objects[index]
        if count == 1 and obj.uncertainty is None:
            return self
        alone = dataclasses.replace(obj, uncertainty=None)
        return dataclasses.replace(self, objects=(alone,), uncertainty=self.uncertainties[index])

    # ---------------------------------------------------------------- observation bounds
    def observation_reach(self) -> Reach:
        """The largest magnitude each part of an observation can take within ``max_steps`` steps
        (:func:`risk_env.scenario.reach.observation_reach`): ``{part: (reach, bound, unit, fields)}``."""
        return observation_reach(self)

    # ---------------------------------------------------------------- building
    @classmethod
    def preset(cls, uncertainty: str = "low", scene: str = "paper", **overrides: Any) -> Scenario:
        """The paper's scenario at an uncertainty level of Table I, with the objects of ``scene``
        (:data:`risk_env.scenario.scenes.SCENE_NAMES`; ``"paper"``: its one object) and named overrides.

        Overrides are flat names (see :data:`OVERRIDES`), e.g. ``ego_start=(x, y, theta)``,
        ``object_speed=2.5`` (the first object), ``objects=[...]``, ``v_ref=3.0``,
        ``severity="plastic"``, ``horizon=8``.
        """
        u = Uncertainty.preset(uncertainty)
        return cls(uncertainty=u, objects=scene_objects(scene)).replace(**overrides)

    def replace(self, **overrides: Any) -> Scenario:
        """A copy with flat-named fields replaced; unknown names raise with suggestions.

        ``objects=[...]`` replaces the objects; ``object_speed=...`` and the other ``object_*``
        names then change the first of them."""
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
        first = nested.pop("object", None)
        for part, changes in nested.items():
            top[part] = dataclasses.replace(getattr(self, part), **changes)
        if first is not None:
            objects = self.objects
            if "objects" in top:
                objects = make_objects(top["objects"], top.get("uncertainty", self.uncertainty))
            top["objects"] = (dataclasses.replace(objects[0], **first), *objects[1:])
        return dataclasses.replace(self, **top)


def make_objects(value: Any, uncertainty: Uncertainty) -> tuple[CrossingObject, ...]:
    """The objects of ``objects=value``: a non-empty sequence of :class:`CrossingObject` or dicts
    of :data:`OBJECT_KEYS` (uncertainty keys start from the object's ``"uncertainty"``, else from
    ``uncertainty``). Errors name the object and the field: ``objects[1].speed must be a real
    number (int or float), got None (NoneType)``."""
    if isinstance(value, tuple) and value and all(type(o) is CrossingObject for o in value):
        return value
    if isinstance(value, (str, bytes, Mapping, CrossingObject)) or not isinstance(
        value, (Sequence, np.ndarray)
    ):
        raise TypeError(
            "objects must be a sequence of CrossingObject or dicts of their fields, got"
            f" {checks.describe(value)}"
        )
    if len(value) == 0:
        raise ValueError("objects must hold at least one object, got an empty sequence")
    return tuple(_make_object(spec, f"objects[{i}]", uncertainty) for i, spec in enumerate(value))


def _make_object(spec: Any, name: str, uncertainty: Uncertainty) -> CrossingObject:
    """One object of :func:`make_objects`, checked under the name ``name``."""
    if isinstance(spec, CrossingObject):
        return spec
    if not isinstance(spec, Mapping):
        raise TypeError(
            f"{name} must be a CrossingObject or a dict of its fields, got {checks.describe(spec)}"
        )
    spec = dict(spec)
    for key in spec:
        if key not in OBJECT_KEYS:
            close = difflib.get_close_matches(str(key), OBJECT_KEYS, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise TypeError(f"unknown key {key!r} in {name}{hint} Valid keys: {list(OBJECT_KEYS)}")
    spread = {k: spec.pop(k) for k in UNCERTAINTY_FIELDS if k in spec}
    own = spec.pop("uncertainty", None)
    if isinstance(own, str):
        checks.text(f"{name}.uncertainty", own, UNCERTAINTY_PRESETS)
        own = Uncertainty.preset(own)
    elif own is not None and not isinstance(own, Uncertainty):
        raise TypeError(
            f"{name}.uncertainty must be an Uncertainty, a preset name {UNCERTAINTY_PRESETS} or None,"
            f" got {checks.describe(own)}"
        )
    if spread:
        own = object.__new__(Uncertainty)  # checked under the object's name, then built
        own.__dict__.update({**vars(uncertainty if own is None else own), **spread})
        check_uncertainty(own, f"{name}.uncertainty")
        own = Uncertainty(**vars(own))
    obj = object.__new__(CrossingObject)
    obj.__dict__.update({**vars(CrossingObject()), **spec, "uncertainty": own})
    check_object(obj, name)  # names objects[i].field, then the real construction
    return CrossingObject(**vars(obj))


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
    "curvature_max": ("ego", "curvature_max"),
    "ego_discs": ("ego", "discs"),
    "ego_length": ("ego", "length"),
    "objects": (None, "objects"),
    "object_start": ("object", "start"),
    "object_speed": ("object", "speed"),
    "object_turn_rate": ("object", "turn_rate"),
    "object_radius": ("object", "radius"),
    "object_mass": ("object", "mass"),
    "object_discs": ("object", "discs"),
    "object_length": ("object", "length"),
    "sigma_growth": ("uncertainty", "sigma_growth"),
    "box_growth": ("uncertainty", "box_growth"),
    "sigma0": ("uncertainty", "sigma0"),
    "box_half_width0": ("uncertainty", "box_half_width0"),
    "velocity_bounds0": ("uncertainty", "velocity_bounds0"),
    "goal": ("path", "goal"),
    "curvature": ("path", "curvature"),
    "lambda_start": ("path", "lambda_start"),
    "corridor": ("path", "corridor"),
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
"""Flat override names accepted by :meth:`Scenario.preset`, the env and the agents. The
``object_*`` names change the first object (:attr:`Scenario.object`); ``objects`` all of them."""
