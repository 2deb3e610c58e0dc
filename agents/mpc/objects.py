"""The MPC's object slots: each slot's estimators (numeric and symbolic), the slots' risk rows
and the numbers a step hands the solver.

An agent has K object slots, fixed at construction (``object_slots``; by default the scenario's
number of objects). Slot k takes object k's radius, mass and uncertainty; slots beyond the
scenario's objects take the last object's (:func:`agents.mpc.nlp.parameters.slot_numbers`). In the
solver these
numbers are parameters, so one built solver serves every scene with up to K objects.

- :func:`symbolic` makes an estimator whose collision distance and object mass are CasADi
  symbols (the solver's parameters), every other number its own.
- :func:`combine` adds the slots' numeric risks of the present objects: R = sum_k R_k, the
  expected total harm (:mod:`risk_env.risk.total_risk`).
"""

from __future__ import annotations

import copy
from typing import Any

import casadi as ca
import numpy as np

from risk_env.risk.estimators import RiskEstimator
from risk_env.risk.severity import InjurySeverity, PaperSeverity, PlasticSeverity
from risk_env.scenario.scenario import Scenario


def slot_scenario(scenario: Scenario, slot: int) -> Scenario:
    """The single-object scenario of slot ``slot``: the scenario itself with one object, else
    ``scenario.for_object(k)`` with k = min(slot, objects - 1)."""
    if len(scenario.objects) == 1:
        return scenario
    return scenario.for_object(min(slot, len(scenario.objects) - 1))


def symbolic(estimator: RiskEstimator, radius: ca.SX, mass: ca.SX) -> RiskEstimator:
    """A copy of ``estimator`` with collision distance ``radius`` [m] and object mass ``mass``
    [kg] (symbols; the severity's scale stays the estimator's, a number)."""
    out = copy.copy(estimator)
    out.radius = radius
    sev, sc = estimator.severity, estimator.scenario
    m_e = sc.ego.mass
    if isinstance(sev, PaperSeverity):
        out.severity = PaperSeverity(m_e, mass)
    elif isinstance(sev, PlasticSeverity):
        out.severity = PlasticSeverity(m_e, mass)
    elif isinstance(sev, InjurySeverity):
        out.severity = InjurySeverity(m_e, mass, sev.beta0, sev.beta1)
    return out


def slot_rows(data: ca.SX, slot: int, rows: int) -> ca.SX:
    """Slot ``slot``'s block ``(rows, 3)`` of one stage's risk data ``(K rows, 3)``."""
    return data[slot * rows : (slot + 1) * rows, :]


def combine(terms: list[np.ndarray]) -> np.ndarray:
    """R = sum over the present slots' risks ``(N,)`` (left to right: one term is itself); zeros
    when none is present."""
    if not terms:
        return np.zeros(0)
    out = np.asarray(terms[0], float).copy()
    for t in terms[1:]:
        out = out + np.asarray(t, float)
    return out


def check_slots(value: Any, scenario: Scenario) -> int:
    """``object_slots`` checked: an integer >= 1 (None: the scenario's number of objects)."""
    if value is None:
        return len(scenario.objects)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"object_slots must be an integer >= 1 (or None), got {value!r}")
    return int(value)
