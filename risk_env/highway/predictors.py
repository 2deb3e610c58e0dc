"""The predictor of the other vehicles in a highway-env world, by name or instance:
``"lane"`` (:class:`risk_env.highway.lanes.LanePredictor`, on the env's road network: the map),
``"constant"`` or None (the paper's, built into the risk and the MPCs), or any
:class:`~risk_env.prediction.predictors.Predictor`."""

from __future__ import annotations

from typing import Any

from risk_env import checks
from risk_env.highway.common import policy_period, unwrapped_highway
from risk_env.prediction.predictors import PREDICTOR_NAMES, Predictor

HIGHWAY_PREDICTORS: tuple[str, ...] = PREDICTOR_NAMES
"""The predictors a highway-env world offers by name: ``"constant"`` and ``"lane"``."""


def highway_predictor(predictor: str | Predictor | None, env: Any) -> Predictor | None:
    """The predictor named ``predictor`` for ``env``'s road network and step, an instance as is,
    or None for the paper's (``None`` or ``"constant"``); an unknown name raises ``ValueError``
    naming it."""
    if predictor is None or isinstance(predictor, Predictor):
        return predictor
    name = checks.text("predictor", predictor, HIGHWAY_PREDICTORS)
    if name == "constant":
        return None
    from risk_env.highway.lanes import LanePredictor

    return LanePredictor(unwrapped_highway(env).road.network, policy_period(env))
