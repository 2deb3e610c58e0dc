"""Gymnasium's vector-env conventions for :mod:`risk_env.vector_env`: the autoreset mode given by
name, and infos masked per copy (the ``final_info`` of same-step autoreset)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode


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
