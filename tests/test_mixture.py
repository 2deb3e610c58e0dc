"""The prediction interface: mixtures of modes and the paper's predictor behind it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from risk_env import Scenario
from risk_env.prediction import (
    Belief,
    ConstantPredictor,
    Mixture,
    Mode,
    Predictor,
    make_predictor,
    predict_array,
)


def _beliefs(scenario: Scenario, m: tuple[float, ...] = (5.0, -5.0, math.pi / 2, 3.0, 1e-4)) -> Belief:
    return predict_array(scenario, np.array(m))


def test_the_constant_predictor_is_the_papers_prediction() -> None:
    scenario = Scenario.preset("medium")
    mixture = ConstantPredictor(scenario).predict((5.0, -5.0, math.pi / 2, 3.0, 1e-4), scenario.horizon)
    assert len(mixture) == 1 and mixture.weights.tolist() == [1.0] and mixture.steps == scenario.horizon
    expected = _beliefs(scenario).as_array()
    np.testing.assert_array_equal(mixture.modes[0].beliefs.as_array(), expected)  # bit for bit
    at2 = mixture.at(2)[0][1]
    assert at2.x == expected[2, 0] and at2.half_y == _beliefs(scenario)[2].half_y


def test_make_predictor_by_name_and_instance() -> None:
    scenario = Scenario.preset("low")
    assert isinstance(make_predictor(None, scenario), ConstantPredictor)
    assert isinstance(make_predictor("constant", scenario), ConstantPredictor)
    mine = ConstantPredictor(scenario)
    assert make_predictor(mine, scenario) is mine
    with pytest.raises(ValueError, match="unknown predictor 'lanes'.*did you mean 'lane'"):
        make_predictor("lanes", scenario)
    with pytest.raises(ValueError, match="road network"):
        make_predictor("lane", scenario)
    with pytest.raises(TypeError, match="predictor must be a string"):
        make_predictor(3, scenario)


def test_a_user_predictor_fits_the_interface() -> None:
    scenario = Scenario.preset("low")

    class TwoWays(Predictor):
        name = "two_ways"

        def predict(self, measurement, steps):
            left = _beliefs(scenario, tuple(measurement))
            right = _beliefs(scenario, (*measurement[:2], measurement[2] - 0.5, *measurement[3:]))
            return Mixture((Mode(0.25, left, "left"), Mode(0.75, right, "right")))

    mixture = TwoWays().predict((0.0, 0.0, 0.0, 2.0, 0.0), 6)
    assert mixture.most_likely().label == "right"
    assert [m.label for m in mixture.above(0.3)] == ["right"]
    assert [m.label for m in mixture.above(0.8)] == ["right"]  # none reaches it: the most likely
    assert mixture.sample_mode(0.1).label == "left" and mixture.sample_mode(0.3).label == "right"


@pytest.mark.parametrize(
    ("weights", "match"),
    [
        ((0.5, 0.6), "sum to 1"),
        ((-0.1, 1.1), r"modes\[0\].weight must be a finite number >= 0"),
        ((float("nan"), 1.0), r"modes\[0\].weight"),
    ],
)
def test_bad_weights_are_named(weights, match) -> None:
    b = _beliefs(Scenario.preset("low"))
    with pytest.raises(ValueError, match=match):
        Mixture(tuple(Mode(w, b) for w in weights))


def test_bad_spreads_and_lengths_are_named() -> None:
    scenario = Scenario.preset("low")
    b = _beliefs(scenario)
    negative = b.as_array() * np.where(np.arange(b.as_array().shape[-1]) == 4, -1.0, 1.0)
    with pytest.raises(ValueError, match=r"Belief.sigma_x must be finite and >= 0"):
        Belief.from_array(negative)  # a Belief of numbers checks itself
    bad = Belief.unchecked(**dict(vars(Belief.from_array(np.abs(negative))), sigma_x=negative[..., 4]))
    with pytest.raises(ValueError, match=r"modes\[1\].beliefs.sigma_x must be finite and >= 0"):
        Mixture((Mode(0.5, b), Mode(0.5, bad)))
    short = Belief.from_array(b.as_array()[:3])
    with pytest.raises(ValueError, match="same prediction steps"):
        Mixture((Mode(0.5, b), Mode(0.5, short)))
    with pytest.raises(ValueError, match="at least one Mode"):
        Mixture(())
    with pytest.raises(ValueError, match="threshold must lie in"):
        Mixture.single(b).above(1.5)
