"""``RiskCostWrapper``: our risk as a cost signal for any highway-env environment."""

from __future__ import annotations

import math
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from risk_env import checks
from risk_env.highway.common import highway_scenario, policy_period, unwrapped_highway, vehicle_measurement
from risk_env.highway.predictors import HIGHWAY_PREDICTORS, highway_predictor
from risk_env.prediction.belief import Belief, predict
from risk_env.prediction.predictors import Predictor
from risk_env.risk.estimators import RiskEstimator, make_estimator
from risk_env.risk.mixture_risk import mixture_risk
from risk_env.scenario.scenario import Scenario


class RiskCostWrapper(gym.Wrapper):
    r"""Adds the paper's collision risk between the controlled vehicle and every other vehicle.

    After each step, for every vehicle $j$ that was on the road before the step, the term
    $R_j = E[I_C s]$ is what ``RiskCrossing-v0`` reports as $R_{k+1|k}$: the one-step belief
    ``predict(scenario, m_j, steps=1)[1]`` from $j$'s measurement $m_j$ *before* the step
    (:func:`risk_env.highway.vehicle_measurement`: position, direction of travel, speed, turn
    rate), evaluated by the estimator at the controlled vehicle's state *after* the step
    $(c_1, c_2, \theta, v)$. Vehicles are discs of ``scenario.ego.radius`` and
    ``scenario.object.radius`` (1.5 m unless overridden: highway-env's 5 x 2 m rectangles touch at
    centre distances from 2 to 5.4 m).

    ``info`` gains

    | key | value |
    | --- | --- |
    | ``risk``, ``cost`` | $\sum_j R_j$ (float; units of the severity, J for the paper's) |
    | ``risk_violation`` | ``risk > scenario.risk_tolerance`` (bool) |
    | ``risk_terms`` | $R_j$ by $j$'s index in ``env.unwrapped.road.vehicles`` after the step (dict) |

    Actions are checked against the env's action space before highway-env sees them: a ``Box``
    takes finite real numbers of its shape (highway-env clips their range itself), a ``Discrete``
    an integer in range (not a bool, not a float); anything else raises ``ValueError`` or
    ``TypeError`` naming the action.

    Vehicles that appeared during the step have no measurement before it and no term (one step
    later they do); road objects (obstacles) are not vehicles and have none. ``reset`` reports
    risk 0 and no terms.

    Args:
        env: a highway-env environment (anything whose ``unwrapped`` has ``controlled_vehicles``).
        uncertainty: the paper's preset, ``"low"``, ``"medium"`` or ``"high"`` (per env step).
        estimator: ``"exact"``, ``"monte_carlo"``, ``"worst_case"`` or ``"grid"``; Monte Carlo
            draws come from the wrapper's own generator (re-seeded by ``reset(seed=...)``), never
            from the env's, so the simulation is the same with any estimator.
        risk_tolerance: $\epsilon$ for ``risk_violation``.
        vehicle_index: which controlled vehicle is the ego (multi-agent envs).
        scenario: a whole :class:`~risk_env.Scenario` instead of ``uncertainty``, ``risk_tolerance``
            and ``overrides``; its ``dt`` must be the env's step (:func:`policy_period`).
        seed: seed of the wrapper's generator until ``reset(seed=...)`` re-seeds it.
        predictor: the vehicles' one-step beliefs: None or ``"constant"`` (the paper's), ``"lane"``
            (:class:`risk_env.highway.lanes.LanePredictor` on the env's road network) or any
            :class:`risk_env.prediction.Predictor`; a mixture's risk is $\sum_m w_m R_m$ (the
            worst case over the modes for a worst-case estimator).
        **overrides: flat scenario parameters (:data:`risk_env.scenario.scenario.OVERRIDES`), on top of
            :func:`risk_env.highway.highway_scenario`'s.
    """

    def __init__(
        self,
        env: gym.Env,
        uncertainty: str = "low",
        estimator: str = "exact",
        risk_tolerance: float = 0.0,
        vehicle_index: int = 0,
        scenario: Scenario | None = None,
        seed: int | None = None,
        predictor: str | Predictor | None = None,
        **overrides: Any,
    ) -> None:
        super().__init__(env)
        unwrapped_highway(env)
        if scenario is None:
            scenario = highway_scenario(env, uncertainty, risk_tolerance, **overrides)
        elif overrides:
            raise TypeError(
                f"pass either scenario= or scenario parameters, not both; got {sorted(overrides)}"
            )
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a risk_env.Scenario, got {type(scenario).__name__}")
        vehicle_index = checks.integer("vehicle_index", vehicle_index, minimum=0)
        if seed is not None:
            seed = checks.integer("seed", seed, minimum=0)
        period = policy_period(env)
        if not math.isclose(scenario.dt, period, rel_tol=1e-9):
            raise ValueError(
                f"scenario.dt = {scenario.dt:g} s, but one step of the env lasts {period:g} s"
                " (simulation_frequency // policy_frequency frames): the risk predicts one env step"
                " ahead; build the scenario with risk_env.highway.highway_scenario(env, ...)"
            )
        self.scenario = scenario
        self.estimator: RiskEstimator = make_estimator(estimator, scenario)
        self.vehicle_index = vehicle_index
        self._rng = np.random.default_rng(seed)
        self._before: list[tuple[Any, np.ndarray]] = []
        self._predictor_arg = predictor
        self.predictor: Predictor | None = None
        """The vehicles' predictor (None: the paper's); a named one is built on the road network at
        the first ``reset``."""
        if predictor is not None and not isinstance(predictor, Predictor):
            checks.text("predictor", predictor, HIGHWAY_PREDICTORS)

    @property
    def ego(self) -> Any:
        """The controlled vehicle whose risk is reported."""
        vehicles = unwrapped_highway(self.env).controlled_vehicles
        if len(vehicles) <= self.vehicle_index:
            raise ValueError(
                f"the env has {len(vehicles)} controlled vehicle(s); vehicle_index {self.vehicle_index}"
                " does not exist (the wrapper needs a controlled vehicle: call reset first?)"
            )
        return vehicles[self.vehicle_index]

    def measure(self) -> np.ndarray:
        """Record every other vehicle's measurement now, as the next step's "before"; returns them
        ``(M, 5)``. ``reset`` and ``step`` call it; call it yourself after editing the scene by hand."""
        ego = self.ego
        others = [v for v in unwrapped_highway(self.env).road.vehicles if v is not ego]
        self._before = [(v, vehicle_measurement(v)) for v in others]
        return np.array([m for _, m in self._before]).reshape(-1, 5)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        obs, info = self.env.reset(seed=seed, options=options)
        if self.predictor is None:
            self.predictor = highway_predictor(self._predictor_arg, self.env)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.measure()
        info.update(risk=0.0, cost=0.0, risk_violation=False, risk_terms={})
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Check ``action`` (:func:`risk_env.checks.space_action`; ``None`` is highway-env's "no
        new action"), step the env and add the risk to ``info``."""
        self.ego  # noqa: B018  (raises a clear error when there is no controlled vehicle)
        if action is not None:
            checks.space_action(action, self.action_space)
        obs, reward, terminated, truncated, info = self.env.step(action)
        terms = self.risk_terms()
        risk = float(sum(terms.values()))
        info.update(
            risk=risk, cost=risk, risk_violation=risk > self.scenario.risk_tolerance, risk_terms=terms
        )
        self.measure()
        return obs, reward, terminated, truncated, info

    def risk_terms(self) -> dict[int, float]:
        """$R_j$ by index in ``road.vehicles`` (dict) of the vehicles measured before the step, at the
        controlled vehicle's current state (what ``step`` reports)."""
        vehicles = unwrapped_highway(self.env).road.vehicles
        index = {id(v): i for i, v in enumerate(vehicles)}
        kept = [(index[id(v)], m) for v, m in self._before if id(v) in index]
        if not kept:
            return {}
        ego = vehicle_measurement(self.ego)[:4]
        if self.predictor is not None:  # each vehicle's mixture, seen with the others
            mixtures = self.predictor.predict_scene(np.array([m for _, m in kept]), 1)
            risks = [mixture_risk(self.estimator, ego, mix.at(1), rng=self._rng) for mix in mixtures]
            return {i: float(r) for (i, _), r in zip(kept, risks, strict=True)}
        measurements = np.array([m for _, m in kept]).T  # (5, M): predict takes 5 batched rows
        belief: Belief = predict(self.scenario, measurements, steps=1)[1]
        risks = np.atleast_1d(self.estimator.risk(ego, belief, rng=self._rng))
        return {i: float(r) for (i, _), r in zip(kept, risks, strict=True)}
