"""The hindsight reference of the intersection (benchmarks.highway_hindsight): its copies live the
episode's own future, so the schedule it chose does in the episode what it did in its copy."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("highway_env")

from benchmarks.highway_hindsight import HindsightEgo  # noqa: E402
from risk_env.highway import make_intersection_env  # noqa: E402
from risk_env.highway.idm import reached  # noqa: E402


def drive(env, driver, seed: int) -> tuple[bool, bool, list[float]]:
    """One episode: ``(collision, goal, the ego's speed at each step's end)``."""
    obs, _ = env.reset(seed=seed)
    driver.reset()
    speeds, done = [], False
    while not done:
        obs, _, terminated, truncated, _ = env.step(driver.predict(obs)[0])
        speeds.append(float(env.unwrapped.vehicle.speed))
        done = terminated or truncated
    return bool(env.unwrapped.vehicle.crashed), bool(reached(env, driver.destination)), speeds


def test_a_schedule_that_waits_first_does_in_the_episode_what_it_did_in_its_copy() -> None:
    """Seed 5 of highway-env's defaults: going at once crashes, waiting 2.5 s arrives (found on the
    sixth copy, branched from the waiting one). A clock counted in act() (which runs twice on a
    policy frame) made the episode go later than its copy, and crash."""
    env = make_intersection_env()
    driver = HindsightEgo(env)
    crashed, goal, _ = drive(env, driver, 5)
    assert driver.start == 2.5 and driver.tried == 6
    assert goal and not crashed


def test_without_a_passage_it_waits_at_the_line() -> None:
    """An episode too short for any passage (2 s): every step's schedule is tried, none arrives,
    and the ego waits, stopped before the junction, unharmed."""
    env = make_intersection_env(duration=2.0)
    driver = HindsightEgo(env)
    crashed, goal, speeds = drive(env, driver, 1)
    assert math.isinf(driver.start) and driver.tried == 4
    assert not crashed and not goal
    lane = env.unwrapped.vehicle.lane_index
    assert lane[1].startswith("ir") and speeds[-1] < speeds[0]  # still on its approach, braking
    np.testing.assert_array_equal(driver.predict(None)[0], np.zeros(2, dtype=np.float32))
