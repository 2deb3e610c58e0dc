r"""The layout of the MPC's parameter vector p (one built solver serves every scene up to its slot
count): $\epsilon$, $v_{ref}$, per object slot its measurement, active flag and numbers, the per-stage
risk data, and the risk terms' numbers. :func:`parameter_vector` writes it; the NLP of
:mod:`agents.mpc.nlp.ocp` reads it."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

from risk_env.prediction.belief import Belief
from risk_env.scenario.scenario import Scenario

SLOT_SIZE = 5 + 3 + 13
"""Parameters per object slot: measurement (5), active, collision distance [m], mass [kg],
uncertainty numbers (13)."""
NUMBER_COLUMNS = 3
"""Columns of the slots' numbers the risk rows read: active flag, collision distance $r_e + r_o$ [m],
object mass [kg]; with given beliefs a fourth, the mode's weight w."""
INACTIVE = 1e3
"""Margin units added to an inactive slot's rows (so they hold, whatever the slot's numbers)."""
TERMS = 5
r"""Parameters of the risk terms (:mod:`agents.mpc.nlp.risk_budget`), at the end of p: the budget B'
(B shifted by its spare), the risk spent so far, the normaliser $\nu = 1/\mathrm{scale}$ of the budget row and
accumulator, the row's switch-off (1: the row always holds) and the weight w."""

_UNCERTAINTY_FIELDS = (
    ("sigma0", 3),
    ("sigma_growth", 3),
    ("box_half_width0", 2),
    ("box_growth", 3),
    ("velocity_bounds0", 2),
)


UNCERTAINTY_NUMBERS = sum(length for _, length in _UNCERTAINTY_FIELDS)
"""How many numbers of a slot describe its uncertainty (13)."""


def uncertainty_vector(scenario: Scenario, index: int = 0) -> np.ndarray:
    """Object ``index``'s :class:`~risk_env.scenario.scenario.Uncertainty` (the first object's by default)
    as the solver's parameter vector (13,)."""
    u = scenario.uncertainties[index]
    return np.concatenate([np.asarray(getattr(u, name), float) for name, _ in _UNCERTAINTY_FIELDS])


def slot_numbers(scenario: Scenario, slots: int) -> np.ndarray:
    """The fixed numbers of each slot ``(K, 2 + 13)``: collision distance $r_e + r_o$ [m], mass $m_o$
    [kg] and uncertainty numbers; slot k takes object k's, the slots beyond the scenario's
    objects the last object's."""
    out = []
    for k in range(slots):
        i = min(k, len(scenario.objects) - 1)
        obj = scenario.objects[i]
        out.append([scenario.collision_distances[i], obj.mass, *uncertainty_vector(scenario, i)])
    return np.array(out, dtype=float)


def parameter_vector(
    epsilon: float,
    v_ref: float,
    measurements: np.ndarray,
    active: np.ndarray,
    numbers: np.ndarray,
    data: np.ndarray,
    terms: np.ndarray | None = None,
) -> np.ndarray:
    r"""The solver's ``p``, the one layout of the module: $\epsilon$, $v_{ref}$ [m/s], per slot k its
    measurement ``measurements[k]`` (5,), its ``active[k]`` flag and its ``numbers[k]``
    (:func:`slot_numbers`: $r_e + r_o$, $m_o$, uncertainty (13,)), together :data:`SLOT_SIZE`; then
    the per-stage risk data ``(N, K J, 3)`` (each stage's matrix column by column); last the
    :data:`TERMS` numbers (``terms``; empty or None without a budget or weight)."""
    blocks = [
        np.concatenate([m, [float(a)], n[:2], n[2:]])
        for m, a, n in zip(measurements, active, numbers, strict=True)
    ]
    tail = np.zeros(0) if terms is None else np.asarray(terms, float)
    return np.concatenate([[epsilon, v_ref], *blocks, *(d.ravel(order="F") for d in data), tail])


def symbolic_uncertainty(p: Any) -> SimpleNamespace:
    """An uncertainty whose numbers are the entries of ``p`` (as :func:`uncertainty_vector` lays
    them out), for :func:`risk_env.predict`."""
    out, i = {}, 0
    for name, length in _UNCERTAINTY_FIELDS:
        out[name] = tuple(p[i + k] for k in range(length))
        i += length
    return SimpleNamespace(**out)


def given_size(horizon: int) -> int:
    r"""Parameters per slot of given beliefs: the weight w and the belief fields at $n = 1, \dots, N$."""
    return 1 + horizon * Belief.SIZE


def given_vector(weights: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
    r"""The given beliefs' block at the end of p: per slot k its weight ``weights[k]`` and its
    belief fields at $n = 1, \dots, N$, ``beliefs (K, N, Belief.SIZE)`` (``Belief.as_array`` order)."""
    weights = np.asarray(weights, float)
    beliefs = np.asarray(beliefs, float)
    return np.concatenate([np.concatenate([[w], b.ravel()]) for w, b in zip(weights, beliefs, strict=True)])
