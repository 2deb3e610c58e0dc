"""What the env and the agents believe about a road user over the horizon.

- :mod:`~risk_env.prediction.belief`: :class:`Belief`, the truncated Gaussians of one prediction
  step, and the paper's constant-input prediction (:func:`predict`);
- :mod:`~risk_env.prediction.mixture`: a belief over the horizon as a weighted mixture of modes;
- :mod:`~risk_env.prediction.predictors`: the predictor interface and the paper's predictor.
"""

from risk_env.prediction.belief import Belief, predict, predict_array, predict_step
from risk_env.prediction.mixture import Mixture, Mode
from risk_env.prediction.predictors import PREDICTOR_NAMES, ConstantPredictor, Predictor, make_predictor

__all__ = [
    "PREDICTOR_NAMES",
    "Belief",
    "ConstantPredictor",
    "Mixture",
    "Mode",
    "Predictor",
    "make_predictor",
    "predict",
    "predict_array",
    "predict_step",
]
