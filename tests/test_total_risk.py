"""The risk among many objects: each object's term with its own numbers, summed; the sum is the
expected total harm of the step (against a large Monte Carlo run of the whole step)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from risk_env import ENV_ID, ESTIMATOR_NAMES, Scenario, make_estimator, predict
from risk_env.risk.total_risk import make_estimators, total

# Two objects flanking the ego's line one step ahead (after 4 m/s for 0.5 s the ego is at (-8, 10)):
# both discs are within reach, each with its own radius, mass and uncertainty.
TWO = [
    {"start": (-6.0, 6.0, math.pi / 2), "speed": 1.0, "radius": 1.0, "mass": 1500.0},
    {"start": (-9.5, 14.5, -math.pi / 2), "speed": 2.0, "radius": 2.0, "mass": 300.0, "uncertainty": "high"},
]


def test_one_estimator_per_object_with_its_radius_mass_and_uncertainty():
    s = Scenario.preset("medium", objects=TWO)
    exact = make_estimators("exact", s)
    assert [e.radius for e in exact] == [2.5, 3.5]
    assert [e.severity.m_o for e in exact] == [1500.0, 300.0]
    assert [e.scenario.uncertainty for e in exact] == [s.uncertainty, s.objects[1].uncertainty]
    assert make_estimators("exact", Scenario.preset("low"))[0].scenario == Scenario.preset("low")


def test_total_adds_left_to_right_and_keeps_a_single_term_exactly():
    assert total([0.1]) == 0.1 and total([0.1, 0.2, 0.3]) == (0.1 + 0.2) + 0.3
    terms = np.array([[1.0, 2.0], [3.0, 4.0]])
    np.testing.assert_array_equal(total(terms), [4.0, 6.0])
    one = np.array([[1.0, 2.0]])
    assert total(one).tolist() == [1.0, 2.0] and total(one).base is None


@pytest.mark.parametrize("estimator", ESTIMATOR_NAMES)
def test_the_env_reports_each_objects_term_and_their_sum(estimator):
    env = gym.make(
        ENV_ID, uncertainty="medium", objects=TWO, risk_estimator=estimator, mc_samples=300
    ).unwrapped
    _, before = env.reset(seed=5)
    measurements = env.object_measurements
    rng = np.random.default_rng(0)
    rng.bit_generator.state = env.np_random.bit_generator.state  # the Monte Carlo draws to come
    _, _, _, _, info = env.step(np.array([4.0, 0.0], dtype=np.float32))
    s = env.scenario
    expected = []
    for i in range(2):
        view = s.for_object(i)
        belief = predict(view, measurements[i], steps=1)[1]
        expected.append(float(make_estimator(estimator, view).risk(info["ego"], belief, rng=rng)))
    assert np.all(np.array(expected) > 0.0), expected  # both objects matter at this step
    np.testing.assert_array_equal(info["risk_terms"], expected)
    assert info["risk"] == info["cost"] == expected[0] + expected[1]
    assert info["episode_risk"] == info["risk"] and before["risk_terms"].tolist() == [0.0, 0.0]


def test_the_sum_is_the_expected_total_harm_of_the_step():
    """Linearity of expectation: E[sum_i I_C,i s_i] over the objects' beliefs, by Monte Carlo."""
    env = gym.make(ENV_ID, uncertainty="medium", objects=TWO).unwrapped
    env.reset(seed=0)
    measurements = env.object_measurements
    _, _, _, _, info = env.step(np.array([4.0, 0.0], dtype=np.float32))
    x, y, _, v = info["ego"]
    s, rng, n = env.scenario, np.random.default_rng(11), 400_000
    harm = np.zeros(n)
    for i, obj in enumerate(s.objects):
        draws = predict(s.for_object(i), measurements[i], steps=1)[1].sample(rng, n)
        hit = np.hypot(x - draws[:, 0], y - draws[:, 1]) <= s.ego.radius + obj.radius
        harm += hit * 0.5 * np.abs(s.ego.mass * v * v - obj.mass * draws[:, 2] ** 2)
    stderr = harm.std() / math.sqrt(n)
    assert abs(harm.mean() - info["risk"]) < 5 * stderr
    assert info["risk_terms"].min() > 10 * stderr  # the check sees both terms


def test_collision_distance_and_closest_object_over_every_object():
    objects = [{"start": (40.0, -20.0, 1.57)}, {"start": (-6.0, 10.5, 0.0), "speed": 0.0, "radius": 0.5}]
    env = gym.make(ENV_ID, objects=objects).unwrapped
    _, info = env.reset(seed=0)
    assert info["closest_object"] == 1 and info["distance"] == pytest.approx(math.hypot(4.0, 0.5))
    _, _, terminated, _, info = env.step(np.array([4.0, 0.0], dtype=np.float32))  # to (-8, 10)
    assert info["distance"] == pytest.approx(math.hypot(2.0, 0.5)) and info["closest_object"] == 1
    assert not info["collision"] and not terminated  # 2.06 m > r_e + r_o,1 = 2 m
    _, _, terminated, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))  # to (-7.5, 10)
    assert info["collision"] and terminated and info["closest_object"] == 1
