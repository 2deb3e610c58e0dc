"""RiskCrossing: the paper's crossing-object scenario (one road user or several), its models and
risk estimators.

Importing the package registers ``"RiskCrossing-v0"`` with Gymnasium (safe to import twice), with
its batched numpy form as the ``vector_entry_point`` of ``gym.make_vec``.
"""

import gymnasium as _gym

from risk_env.envs.env import ENV_ID, OBJECT_MOTIONS, RiskCrossingEnv
from risk_env.envs.variations import Variations
from risk_env.prediction.belief import Belief, predict, predict_array
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
from risk_env.scenario.parts import CrossingObject
from risk_env.scenario.scenario import RISK_TOLERANCES, UNCERTAINTY_PRESETS, Scenario
from risk_env.scenario.scenes import SCENE_NAMES

__all__ = [
    "ENV_ID",
    "ESTIMATOR_NAMES",
    "OBJECT_MOTIONS",
    "RISK_TOLERANCES",
    "SCENE_NAMES",
    "UNCERTAINTY_PRESETS",
    "Belief",
    "CrossingObject",
    "ExactRisk",
    "MonteCarloRisk",
    "RiskCrossingEnv",
    "RiskEstimator",
    "Scenario",
    "Severity",
    "Variations",
    "WorstCaseRisk",
    "make_estimator",
    "make_estimators",
    "make_severity",
    "predict",
    "predict_array",
]

if ENV_ID not in _gym.registry:
    _gym.register(
        id=ENV_ID,
        entry_point="risk_env.envs.env:RiskCrossingEnv",
        vector_entry_point="risk_env.envs.vector_env:RiskCrossingVectorEnv",
    )
