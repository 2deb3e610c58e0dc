"""The metadata saved beside a PPO policy (``policy.json`` beside ``policy.zip``), read and checked.

:func:`benchmarks.train_ppo` writes it: the training arguments (``args``), the input limits the
policy acts within (``limits``), the feature count (``features``) and, for a tolerance-conditioned
policy, its :class:`agents.ppo.policy.FeatureSpec` (``feature_spec``). A damaged file is named in the error,
never half read.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from risk_env import checks

SECTIONS: dict[str, type] = {"args": dict, "limits": dict, "feature_spec": dict, "features": int}
"""The entries :class:`agents.ppo.policy.PPOAgent` reads, with their JSON types (others are kept)."""


def read_metadata(path: Path) -> dict[str, Any]:
    """The metadata object at ``path`` (``{}`` without a file; ``feature_spec["steps"]`` a tuple);
    ``ValueError`` naming the file for text that is not JSON, a value that is not an object, or an
    entry of :data:`SECTIONS` of another type (``limits`` must hold numbers)."""
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not valid JSON ({exc}): restore the file train_ppo wrote") from None
    if not isinstance(data, dict):
        raise ValueError(
            f"{path} must hold a JSON object (the policy's metadata), got {checks.describe(data)}"
        )
    for key, kind in SECTIONS.items():
        if key in data and (not isinstance(data[key], kind) or isinstance(data[key], bool)):
            raise ValueError(
                f"{path}: {key!r} must be a JSON {'object' if kind is dict else 'integer'},"
                f" got {checks.describe(data[key])}"
            )
    spec = data.get("feature_spec", {})
    if isinstance(spec.get("steps"), list):  # JSON has no tuples
        spec["steps"] = tuple(spec["steps"])
    for name, value in data.get("limits", {}).items():
        if not checks.is_real(value):
            raise ValueError(f"{path}: limits[{name!r}] must be a number, got {checks.describe(value)}")
    return data


def build(path: Path, what: str, make: Any, values: dict[str, Any]) -> Any:
    """``make(**values)``, the ``what`` of the metadata at ``path``; ``ValueError`` naming the file
    and the entry when its keys or values do not fit."""
    try:
        return make(**values)
    except (TypeError, ValueError, KeyError) as exc:
        raise ValueError(f"{path}: {what} {values!r} does not fit ({exc})") from None
