"""The env's constructor arguments that build its scenario and its observation: a preset with a
scene and overrides, or a whole :class:`~risk_env.scenario.scenario.Scenario`; and the object slots."""

from __future__ import annotations

import difflib
import math
from collections.abc import Sequence
from typing import Any

from risk_env import checks
from risk_env.envs.variations import Variations
from risk_env.prediction.predictors import Predictor, make_predictor
from risk_env.scenario.scenario import OVERRIDES, Scenario


def build_scenario(
    uncertainty: str | None,
    risk_tolerance: float | None,
    scenario: Scenario | None,
    scene: str | None,
    overrides: dict[str, Any],
    env_arguments: Sequence[str],
) -> Scenario:
    """The env's scenario from either ``scenario`` or a preset with a scene and overrides; clear
    errors for unknown names (with suggestions among ``env_arguments`` and the overrides) and for
    a scenario given together with preset arguments."""
    unknown = [name for name in overrides if name not in OVERRIDES]
    if unknown:
        known = [*OVERRIDES, *env_arguments]
        hints = []
        for name in unknown:
            close = difflib.get_close_matches(name, known, n=3)
            hints.append(f"{name!r}" + (f" (did you mean {', '.join(close)}?)" if close else ""))
        raise TypeError(
            f"RiskCrossingEnv got unknown keyword argument(s) {', '.join(hints)}. Env arguments:"
            f" {sorted(env_arguments)}; scenario parameters: {sorted(OVERRIDES)}"
        )
    if scenario is not None:
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a risk_env.Scenario, got {type(scenario).__name__}")
        given = [
            name
            for name, value in (
                ("uncertainty", uncertainty),
                ("risk_tolerance", risk_tolerance),
                ("scene", scene),
            )
            if value is not None
        ]
        given += sorted(overrides)
        if given:
            raise TypeError(
                f"pass either scenario= or uncertainty/risk_tolerance/scene/scenario parameters, not"
                f" both; got scenario= and {given}. Use scenario.replace(...) to change a scenario."
            )
        return scenario
    if risk_tolerance is not None:
        overrides = {**overrides, "risk_tolerance": risk_tolerance}
    return Scenario.preset(
        "low" if uncertainty is None else uncertainty, "paper" if scene is None else scene, **overrides
    )


def slot_count(value: Any, scenario: Scenario) -> int:
    r"""The observation's object slots $K$: ``value`` (an integer $\ge 1$), or None: one per object of
    ``scenario``. Raises when the scenario has more objects than slots (none is dropped)."""
    count = len(scenario.objects)
    if value is None:
        return count
    slots = checks.integer("object_slots", value, minimum=1)
    if count > slots:
        raise ValueError(
            f"the scenario has {count} objects but object_slots = {slots}: objects[{slots}]"
            f"{f'..objects[{count - 1}]' if count - 1 > slots else ''} would have no observation slot;"
            f" pass object_slots >= {count} (nothing is dropped silently)"
        )
    return slots


def check_variations(variations: Any, randomize: bool) -> Variations:
    """The env's ``variations``: a :class:`~risk_env.envs.variations.Variations`, given only with
    ``randomize=True``; None: the defaults."""
    if variations is not None and not isinstance(variations, Variations):
        raise TypeError(f"variations must be a risk_env.Variations, got {type(variations).__name__}")
    if variations is not None and not randomize:
        raise ValueError("variations= is used only with randomize=True")
    return Variations() if variations is None else variations


def check_weight(value: Any) -> float:
    r"""The env's ``reward_risk_weight``: a finite number $\ge 0$."""
    weight = checks.real("reward_risk_weight", value)
    if not (math.isfinite(weight) and weight >= 0.0):
        raise ValueError(f"reward_risk_weight must be finite and >= 0, got {value!r}")
    return weight


def check_render_mode(value: Any, modes: Sequence[str]) -> str | None:
    """The env's ``render_mode``: None or one of ``modes``."""
    if value is not None and value not in modes:
        raise ValueError(f"unknown render_mode {value!r}; expected None or one of {list(modes)}")
    return value


def check_predictor(value: Any, scenario: Scenario) -> Predictor | None:
    """The env's ``predictor``: None for the paper's built-in prediction (``None`` or
    ``"constant"``), else a :class:`~risk_env.prediction.predictors.Predictor`."""
    if value is None or value == "constant":
        return None
    return make_predictor(value, scenario)
