"""The MPCs on any predictor: beliefs and mode weights as solver parameters ("given")."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import risk_env  # noqa: F401  (registers RiskCrossing-v0)
from agents import RMPC, SMPC
from risk_env.prediction import Belief, ConstantPredictor, Mixture, Mode, Predictor, predict_array
from risk_env.risk.estimators import WorstCaseRisk


def _episode(agent, env, steps: int) -> list[np.ndarray]:
    obs, _ = env.reset(seed=0)
    actions = []
    for _ in range(steps):
        action, _ = agent.predict(obs)
        actions.append(action)
        obs, *_ = env.step(action)
    return actions


@pytest.mark.parametrize("make", [RMPC, SMPC], ids=["rmpc", "smpc"])
def test_the_papers_predictor_as_given_beliefs_plans_as_the_built_in_prediction(make) -> None:
    """The paper's prediction handed in as parameters (one mode of weight 1) drives as the
    prediction the NLP makes itself: the same plans to the solver's tolerance."""
    env = gym.make("RiskCrossing-v0", uncertainty="medium", risk_tolerance=1000.0, max_steps=12)
    scenario = env.unwrapped.scenario
    built_in = make(scenario, max_solve_time=math.inf)
    given = make(scenario, max_solve_time=math.inf, predictor=ConstantPredictor(scenario), modes=1)
    a, b = _episode(built_in, env, 12), _episode(given, env, 12)
    np.testing.assert_allclose(np.array(a), np.array(b), atol=1e-3)
    assert given.failures == built_in.failures == 0


class _Forked(Predictor):
    """Two hypotheses: the paper's object straight on, or turned 90 degrees to the ego's side."""

    name = "forked"

    def __init__(self, scenario, weight_turn: float) -> None:
        self.scenario, self.weight_turn = scenario, weight_turn

    def predict(self, measurement, steps):
        m = np.asarray(measurement, float)
        straight = predict_array(self.scenario, m, steps)
        turned = predict_array(self.scenario, np.array([m[0], m[1], m[2] + math.pi / 2, m[3], 0.0]), steps)
        w = self.weight_turn
        return Mixture((Mode(1.0 - w, straight, "straight"), Mode(w, turned, "turn")))


def test_the_rmpc_keeps_off_every_mode_above_the_threshold_and_ignores_the_rest() -> None:
    env = gym.make("RiskCrossing-v0", uncertainty="low", max_steps=6)
    scenario = env.unwrapped.scenario
    obs, _ = env.reset(seed=0)
    worst = WorstCaseRisk(scenario)
    for w, threshold, kept in ((0.2, 0.1, 2), (0.05, 0.1, 1)):
        agent = RMPC(
            scenario, max_solve_time=math.inf, predictor=_Forked(scenario, w), mode_threshold=threshold
        )
        agent.predict(obs)
        report = agent.last_solve
        assert report.fallback is None
        mixture = agent._slots.predictor.predict(obs[11:16], scenario.horizon)
        ego = np.column_stack([report.ego_trajectory[1:], np.r_[report.inputs[:, 0]]])
        clear = [
            worst.distance(ego, Belief.from_array(mode.beliefs.as_array()[1:])) - worst.radius
            for mode in mixture.modes
        ]
        # the modes it plans against: clear of their boxes
        for mode, c in zip(mixture.modes, clear, strict=True):
            if mode.weight >= threshold:
                assert np.all(c >= -1e-6), (w, mode.label, c)
        assert sum(mode.weight >= threshold for mode in mixture.modes) == kept


def test_the_smpc_bounds_the_weighted_sum_of_the_modes_risks() -> None:
    env = gym.make("RiskCrossing-v0", uncertainty="medium", severity="probability", max_steps=6)
    scenario = env.unwrapped.scenario
    obs, _ = env.reset(seed=0)
    epsilon = 0.01
    agent = SMPC(scenario, risk_tolerance=epsilon, max_solve_time=math.inf, predictor=_Forked(scenario, 0.3))
    agent.predict(obs)
    report = agent.last_solve
    assert report.fallback is None
    assert np.all(report.risk <= epsilon + 1e-6), report.risk
    # the report's risk is the weighted sum of the modes' exact risks
    mixture = agent._slots.predictor.predict(obs[11:16], scenario.horizon)
    ego = np.column_stack([report.ego_trajectory[1:], report.inputs[:, 0]])
    expected = sum(
        m.weight * agent.estimator.risk(ego, Belief.from_array(m.beliefs.as_array()[1:]))
        for m in mixture.modes
    )
    np.testing.assert_allclose(report.risk, expected, rtol=1e-9, atol=1e-12)


def test_too_many_modes_and_bad_thresholds_are_named() -> None:
    scenario = risk_env.Scenario.preset("low")
    obs = gym.make("RiskCrossing-v0").reset(seed=0)[0]
    agent = SMPC(scenario, max_solve_time=math.inf, predictor=_Forked(scenario, 0.5), modes=1)
    with pytest.raises(ValueError, match="2 modes; the agent plans against at most modes=1"):
        agent.predict(obs)
    with pytest.raises(ValueError, match=r"mode_threshold must lie in \[0, 1\]"):
        RMPC(scenario, mode_threshold=1.5)
    with pytest.raises(ValueError, match="modes=2 needs a predictor"):
        RMPC(scenario, modes=2)
    with pytest.raises(ValueError, match="unknown predictor"):
        RMPC(scenario, predictor="lanes")
