"""The predictor of the other vehicles in a highway-env world, by name or instance:
``"lane"`` (:class:`risk_env.highway.lanes.LanePredictor`, on the env's road network: the map),
``"lane+interval"`` (the same with the interval prediction over highway-env's IDM parameters, the
env's controlled vehicle taking part as the ego),
``"constant"`` or None (the paper's, built into the risk and the MPCs), or any
:class:`~risk_env.prediction.predictors.Predictor`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from risk_env import checks
from risk_env.highway.common import policy_period, unwrapped_highway, vehicle_measurement
from risk_env.prediction.predictors import PREDICTOR_NAMES, Predictor

HIGHWAY_PREDICTORS: tuple[str, ...] = PREDICTOR_NAMES
"""The predictors a highway-env world offers by name: ``"constant"``, ``"lane"`` and
``"lane+interval"``."""


def highway_predictor(
    predictor: str | Predictor | None, env: Any, pieces: int = 1, intervals: Any = None
) -> Predictor | None:
    """The predictor named ``predictor`` for ``env``'s road network and step, an instance as is,
    or None for the paper's (``None`` or ``"constant"``); an unknown name raises ``ValueError``
    naming it. ``pieces``: the lane predictors' P (bands along each route, one mode each);
    ``intervals``: ``"lane+interval"``'s :class:`~risk_env.highway.lanes.interval.IntervalModel`
    (None: its defaults)."""
    if predictor is None or isinstance(predictor, Predictor):
        return predictor
    name = checks.text("predictor", predictor, HIGHWAY_PREDICTORS)
    if name == "constant":
        return None
    from risk_env.highway.lanes import LanePredictor

    network, dt = unwrapped_highway(env).road.network, policy_period(env)
    if name == "lane+interval":
        return LanePredictor(
            network, dt, pieces=pieces, longitudinal="interval", intervals=intervals, ego=ego_reader(env)
        )
    if intervals is not None:
        raise ValueError(f"intervals need the predictor 'lane+interval', got {name!r}")
    return LanePredictor(network, dt, pieces=pieces)


def ego_reader(env: Any) -> Callable[[], np.ndarray | None]:
    """A callable returning the measurement (:func:`~risk_env.highway.common.vehicle_measurement`)
    of ``env``'s controlled vehicle now (None when there is none): the interval prediction's ego."""

    def read() -> np.ndarray | None:
        vehicle = getattr(unwrapped_highway(env), "vehicle", None)
        return None if vehicle is None else vehicle_measurement(vehicle)

    return read
