"""The prediction interface: a predictor maps what is observed of a road user to its belief over
the horizon, a :class:`~risk_env.prediction.mixture.Mixture` of modes.

- :class:`ConstantPredictor` (``"constant"``): the paper's, one mode: the unicycle with the
  measured, constant inputs and the scenario's uncertainty growing on the world's axes
  (:func:`risk_env.prediction.belief.predict`);
- ``"lane"``: highway-env's lanes and routes (:class:`risk_env.highway.lanes.predictor.LanePredictor`;
  it needs a road network, so it is built from highway-env's env, not by name alone);
- ``"lane+interval"``: the same with the interval prediction over highway-env's IDM parameters
  along the lane (``LanePredictor(..., longitudinal="interval")``), also built from the env.

Everything that predicts takes a :class:`Predictor`: the env (its objects' one-step beliefs), the
agents (their plans) and the benchmarks (``python -m benchmarks.prediction``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np

from risk_env import checks
from risk_env.prediction.belief import Belief, predict
from risk_env.prediction.mixture import Mixture
from risk_env.scenario.parts import Uncertainty
from risk_env.scenario.scenario import Scenario

PREDICTOR_NAMES: tuple[str, ...] = ("constant", "lane", "lane+interval")
"""The predictors by name: the paper's, highway-env's lanes, and its lanes with the interval
prediction over the IDM's parameters."""


class Predictor(ABC):
    """Maps a road user's measurement to its belief over the horizon."""

    name: ClassVar[str]
    max_modes: int = 3
    """The most modes a mixture of this predictor has (an agent sizes its mode slots by it)."""

    @abstractmethod
    def predict(self, measurement: Any, steps: int) -> Mixture:
        """The mixture over n = 0..``steps`` for ``measurement = (c1 [m], c2 [m], theta [rad],
        v [m/s], omega [rad/s])`` (5,)."""

    def predict_scene(self, measurements: Any, steps: int) -> list[Mixture]:
        """One mixture per road user of ``measurements (m, 5)``, each seen with the others (a
        predictor of interacting traffic overrides this: a follower brakes behind its leader);
        by default each on its own."""
        rows = np.asarray(measurements, dtype=float).reshape(-1, 5)
        return [self.predict(row, steps) for row in rows]

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class ConstantPredictor(Predictor):
    """The paper's prediction: one mode, the unicycle with the measured constant inputs, the
    spread of ``uncertainty`` (the scenario's first object's by default) growing on the world's
    axes (``frame`` 0)."""

    name = "constant"
    max_modes = 1

    def __init__(self, scenario: Scenario, uncertainty: Uncertainty | None = None) -> None:
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a risk_env Scenario, got {checks.describe(scenario)}")
        if uncertainty is not None and not isinstance(uncertainty, Uncertainty):
            raise TypeError(f"uncertainty must be an Uncertainty or None, got {checks.describe(uncertainty)}")
        self.scenario = scenario
        self.uncertainty = scenario.uncertainties[0] if uncertainty is None else uncertainty

    def predict(self, measurement: Any, steps: int) -> Mixture:
        m = checks.finite_reals("measurement", measurement, 5)
        steps = checks.integer("steps", steps, minimum=0)
        beliefs = predict(self.scenario, m, steps, uncertainty=self.uncertainty)
        stacked = Belief.from_array(np.stack([b.as_array() for b in beliefs]))
        return Mixture.single(stacked, "constant")

    def __repr__(self) -> str:
        return f"ConstantPredictor(uncertainty={self.uncertainty})"


def make_predictor(predictor: str | Predictor | None, scenario: Scenario) -> Predictor:
    """A predictor from a name of :data:`PREDICTOR_NAMES` or an instance (returned as is);
    None: the paper's. ``"lane"`` and ``"lane+interval"`` need highway-env's road network: build
    :class:`risk_env.highway.lanes.predictor.LanePredictor` from the env (or
    :func:`risk_env.highway.highway_predictor`) and pass it."""
    if predictor is None:
        return ConstantPredictor(scenario)
    if isinstance(predictor, Predictor):
        return predictor
    name = checks.text("predictor", predictor, PREDICTOR_NAMES)
    if name in ("lane", "lane+interval"):
        extra = ", longitudinal='interval'" if name == "lane+interval" else ""
        raise ValueError(
            f"predictor={name!r} follows highway-env's lanes and needs its road network: build"
            " risk_env.highway.LanePredictor(env.unwrapped.road.network, risk_env.highway.policy_period(env)"
            f"{extra}) and pass that instance"
        )
    return ConstantPredictor(scenario)
