"""Collision risk $R = E[I_C s]$: the severities, the disc geometry and its quadrature, and the
estimators behind one interface (:class:`RiskEstimator`).

- :mod:`~risk_env.risk.estimators`: exact, Monte Carlo, worst case and grid;
- :mod:`~risk_env.risk.severity`: the severities $s$ and their expectations;
- :mod:`~risk_env.risk.disc`, :mod:`~risk_env.risk.quadrature`, :mod:`~risk_env.risk.exact_kernel`:
  the disc probability (one definition for numpy and CasADi) and its fast numpy kernels;
- :mod:`~risk_env.risk.total_risk`: the sum over every object.
"""

from risk_env.risk.disc import disc_probability, signed_box_distance
from risk_env.risk.estimators import (
    ESTIMATOR_NAMES,
    ExactRisk,
    MonteCarloRisk,
    RiskEstimator,
    WorstCaseRisk,
    make_estimator,
)
from risk_env.risk.severity import Severity, make_severity
from risk_env.risk.total_risk import make_estimators

__all__ = [
    "ESTIMATOR_NAMES",
    "ExactRisk",
    "MonteCarloRisk",
    "RiskEstimator",
    "Severity",
    "WorstCaseRisk",
    "disc_probability",
    "make_estimator",
    "make_estimators",
    "make_severity",
    "signed_box_distance",
]
