r"""The risk of a mixture of modes (:class:`~risk_env.prediction.mixture.Mixture`) with any
estimator of :mod:`risk_env.risk.estimators`.

- An expectation (exact, Monte Carlo): $R = \sum_m w_m R_m$, exact by linearity of expectation
  (the road user follows mode $m$ with probability $w_m$), as the sum over objects is.
- A worst case (worst case, grid): $\max_m R_m$ over the modes of weight at least ``threshold``
  ($w_{\min}$; and above 0): the robust planner's view, no expectation to weigh.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from risk_env.prediction.belief import Belief
from risk_env.risk.bodies import BodyRisk
from risk_env.risk.estimators import RiskEstimator, WorstCaseRisk


def is_expectation(estimator: RiskEstimator) -> bool:
    """Whether ``estimator``'s risk is an expectation (weighted over modes), not a worst case."""
    inner = estimator.inner if isinstance(estimator, BodyRisk) else estimator
    return not isinstance(inner, WorstCaseRisk)


def mixture_risk(
    estimator: RiskEstimator,
    ego: Any,
    modes: Sequence[tuple[float, Belief]],
    threshold: float = 0.0,
    rng: np.random.Generator | None = None,
) -> Any:
    """R of ``ego`` states (as :meth:`RiskEstimator.risk`) against the modes ``[(w_m, belief of
    mode m), ...]`` at one prediction step (:meth:`Mixture.at`); see the module. Monte Carlo
    draws come from ``rng``, mode by mode, in order."""
    if not modes:
        raise ValueError("a mixture has at least one mode")
    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"the mode threshold must lie in [0, 1], got {threshold!r}")
    if len(modes) == 1:  # one mode (the paper's prediction): its risk itself, as the estimator gives it
        return _one(estimator, ego, modes[0][1], rng)
    if is_expectation(estimator):
        total = None
        for w, belief in modes:
            term = w * _one(estimator, ego, belief, rng)
            total = term if total is None else total + term
        return total
    kept = [b for w, b in modes if w > 0 and w >= threshold] or [max(modes, key=lambda m: m[0])[1]]
    worst = None
    for belief in kept:
        r = _one(estimator, ego, belief, rng)
        worst = r if worst is None else np.maximum(worst, r)
    return worst


def _one(estimator: RiskEstimator, ego: Any, belief: Belief, rng: np.random.Generator | None) -> Any:
    if isinstance(ego, np.ndarray):
        return estimator.risk(ego, belief, rng=rng)
    return estimator.risk_one(ego, belief, rng=rng)
