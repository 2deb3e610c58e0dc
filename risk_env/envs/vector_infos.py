"""Gymnasium's vector-env conventions for :mod:`risk_env.envs.vector_env`: the autoreset mode given by
name, the single env's info keys as arrays over copies, and infos masked per copy (the
``final_info`` of same-step autoreset)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

from risk_env.envs.transition import Observed


def parse_autoreset_mode(value: AutoresetMode | str) -> AutoresetMode:
    """``AutoresetMode`` from itself, its value (``"SameStep"``) or its name (``"same_step"``)."""
    if isinstance(value, AutoresetMode):
        return value
    for mode in AutoresetMode:
        if value in (mode.value, mode.name, mode.name.lower()):
            return mode
    names = [m.name.lower() for m in AutoresetMode]
    raise ValueError(f"unknown autoreset_mode {value!r}; expected an AutoresetMode or one of {names}")


def masked(infos: dict[str, Any], mask: np.ndarray) -> dict[str, Any]:
    """A copy of vector ``infos`` whose ``_key`` masks are ``mask`` and whose entries are zero off it
    (Gymnasium's final_info form)."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        if key.startswith("_"):
            out[key] = mask.copy()
        elif isinstance(value, dict):
            out[key] = masked(value, mask)
        else:
            out[key] = where(mask, value, np.zeros_like(value))
    return out


def where(mask: np.ndarray, new: Any, old: Any) -> Any:
    """Entries of ``new`` where ``mask`` (per copy), else ``old``; recurses into dicts."""
    if isinstance(new, dict):
        return {k: (where(mask, new[k], old[k]) if not k.startswith("_") else old[k]) for k in new}
    m = mask.reshape(mask.shape + (1,) * (np.ndim(new) - 1))
    return np.where(m, new, old)


def infos(
    seen: Observed,
    risk: np.ndarray,
    terms: np.ndarray,
    episode_risk: np.ndarray,
    state: np.ndarray,
    present: np.ndarray,
    rewards: dict[str, np.ndarray],
    risk_tolerance: float,
    mask: np.ndarray,
) -> dict[str, Any]:
    """The single env's info keys as arrays over B copies, each with the all-True ``_key``
    ``mask``: from the observed state, the risk ``(B,)`` and its terms ``(M, B)``, the batched
    state ``(5 + 5 M, B)`` and which objects are present ``(B, M)``."""
    count = terms.shape[0]
    objects = state[5:].reshape(count, 5, -1)[:, :4].transpose(2, 0, 1).copy()  # (B, M, 4)
    if count > 1 and not present.all():
        objects *= present[:, :, None]  # zeros for absent objects
    return {
        "risk": risk,
        "_risk": mask,
        "cost": risk.copy(),
        "_cost": mask,
        "risk_terms": terms.T.copy(),
        "_risk_terms": mask,
        "episode_risk": episode_risk.copy(),
        "_episode_risk": mask,
        "risk_violation": risk > risk_tolerance,
        "_risk_violation": mask,
        "collision": seen.collision,
        "_collision": mask,
        "distance": seen.distance,
        "_distance": mask,
        "closest_object": seen.closest,
        "_closest_object": mask,
        "path_error": seen.path_error,
        "_path_error": mask,
        "lambda": seen.lam,
        "_lambda": mask,
        "ego": state[0:4].T.copy(),
        "_ego": mask,
        "object": state[5:9].T.copy(),
        "_object": mask,
        "objects": objects,
        "_objects": mask,
        "present": present,
        "_present": mask,
        "is_success": seen.goal & ~seen.collision,
        "_is_success": mask,
        "rewards": {**rewards, **{f"_{k}": mask for k in rewards}},
        "_rewards": mask,
    }
