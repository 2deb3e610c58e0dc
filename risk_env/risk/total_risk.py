r"""The risk of a step among many road users: one estimator per object, and their sum.

With objects $i = 1, \dots, M$, each with its own belief $B_i$ (from its own measurement and
uncertainty), disc radius $r_{o,i}$ and mass $m_{o,i}$, the step's risk is

$$R = \sum_i R_i, \qquad R_i = E[I_{C,i}(q_e, q_{o,i})\, s_i(v_e, v_{o,i})],$$

$I_{C,i}$ the indicator of $\|q_e - q_{o,i}\| \le r_e + r_{o,i}$ and $s_i$ the severity with object
$i$'s mass. By linearity of expectation, $\sum_i E[I_{C,i} s_i] = E[\sum_i I_{C,i} s_i]$: $R$ is
*exactly* the expected total harm of the step (the severities of every collision it may bring, added), not an
approximation, and it needs no independence between the objects. (It is not the probability of
any collision: with the ``"probability"`` severity, $R$ is the expected number of collisions, an
upper bound on that probability.)

:func:`make_estimators` builds object $i$'s estimator on ``scenario.for_object(i)``
(:meth:`~risk_env.scenario.scenario.Scenario.for_object`), so every estimator of
:mod:`risk_env.risk.estimators`
(exact, Monte Carlo, worst case, grid) serves many objects unchanged; with one object it is
exactly the single-object estimator.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from risk_env.risk.estimators import RiskEstimator, make_estimator
from risk_env.scenario.scenario import Scenario


def make_estimators(name: str, scenario: Scenario, **kwargs: Any) -> tuple[RiskEstimator, ...]:
    """One estimator called ``name`` per object of ``scenario``, in order: object $i$'s on
    ``scenario.for_object(i)`` (its radius $r_e + r_{o,i}$, its mass in the severity, its uncertainty)."""
    return tuple(make_estimator(name, scenario.for_object(i), **kwargs) for i in range(len(scenario.objects)))


def total(terms: Sequence[float] | np.ndarray) -> Any:
    r"""$R = \sum_i R_i$: floats -> a float (left to right, so one term is returned exactly), or
    ``(M, ...)`` arrays -> ``(...)``."""
    if isinstance(terms, np.ndarray):
        return terms.sum(axis=0) if terms.shape[0] > 1 else terms[0].copy()
    out = terms[0]
    for term in terms[1:]:
        out += term
    return out
