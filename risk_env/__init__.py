"""RiskCrossing: the paper's crossing-object scenario, its models and risk estimators."""

from risk_env.prediction import Belief, predict, predict_array
from risk_env.risk import (
    ESTIMATOR_NAMES,
    ExactRisk,
    MonteCarloRisk,
    RiskEstimator,
    WorstCaseRisk,
    make_estimator,
)
from risk_env.scenario import RISK_TOLERANCES, UNCERTAINTY_PRESETS, Scenario
from risk_env.severity import Severity, make_severity

__all__ = [
    "ESTIMATOR_NAMES",
    "RISK_TOLERANCES",
    "UNCERTAINTY_PRESETS",
    "Belief",
    "ExactRisk",
    "MonteCarloRisk",
    "RiskEstimator",
    "Scenario",
    "Severity",
    "WorstCaseRisk",
    "make_estimator",
    "make_severity",
    "predict",
    "predict_array",
]
