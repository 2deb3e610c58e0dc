"""What the agents and the env believe about a road user over the horizon.

- :mod:`~risk_env.prediction.belief`: :class:`Belief`, the truncated Gaussians of one prediction
  step, and the paper's constant-input prediction (:func:`predict`).
"""

from risk_env.prediction.belief import Belief, predict, predict_array, predict_step

__all__ = ["Belief", "predict", "predict_array", "predict_step"]
