"""Seeded scenario variations (``randomize=True``) and the batched path they need."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

from risk_env import ENV_ID, Scenario, Variations
from risk_env.envs.variations import vary
from risk_env.models.path import PathBatch, point, project


def test_zero_variations_give_the_base_scenario() -> None:
    base = Scenario.preset("medium")
    still = Variations(**{f.name: 0.0 for f in dataclasses.fields(Variations) if f.name != "object_count"})
    drawn = vary(base, np.random.default_rng(0), still)
    assert drawn.path == base.path and drawn.object == base.object
    np.testing.assert_allclose(drawn.ego.start.as_tuple(), base.ego.start.as_tuple(), atol=1e-9)


def test_draws_stay_in_their_ranges_and_keep_the_ego_placed_on_the_path() -> None:
    base, ranges = Scenario.preset("low"), Variations()
    lam0 = float(project(base.path, base.ego.start.x, base.ego.start.y))
    rng = np.random.default_rng(1)
    curvatures = []
    for _ in range(200):
        s = vary(base, rng, ranges)
        curvatures.append(s.path.curvature)
        assert abs(s.path.curvature - base.path.curvature) <= ranges.curvature + 1e-12
        assert abs(s.object.start.x - base.object.start.x) <= ranges.object_position
        assert abs(s.object.speed - base.object.speed) <= ranges.object_speed
        lam = float(project(s.path, s.ego.start.x, s.ego.start.y))
        assert abs(lam - lam0) <= ranges.ego_shift + 0.5  # the offset changes the foot point a little
        px, py, _ = point(s.path, lam)
        assert math.hypot(s.ego.start.x - px, s.ego.start.y - py) <= 3.5 + ranges.ego_offset
        assert s.path.goal == base.path.goal and s.uncertainty == base.uncertainty
    assert np.ptp(curvatures) > ranges.curvature  # the draws do spread


def test_bad_variations_raise() -> None:
    with pytest.raises(ValueError, match="Variations.curvature"):
        Variations(curvature=-1.0)
    with pytest.raises(ValueError, match="randomize=True"):
        gym.make(ENV_ID, variations=Variations())
    with pytest.raises(TypeError, match="Variations"):
        gym.make(ENV_ID, randomize=True, variations={"curvature": 0.0})


def test_randomized_env_is_seeded_and_varies() -> None:
    env = gym.make(ENV_ID, randomize=True).unwrapped
    first, _ = env.reset(seed=3)
    scenario = env.scenario
    again, _ = env.reset(seed=3)
    np.testing.assert_array_equal(first, again)
    assert env.scenario == scenario and env.base_scenario == Scenario.preset("low")
    other, _ = env.reset(seed=4)
    assert not np.array_equal(first, other) and env.scenario != scenario
    # the observation's path error is measured against the episode's own path
    lam = float(project(env.scenario.path, other[0], other[1]))
    px, py, _ = point(env.scenario.path, lam)
    np.testing.assert_allclose(other[6:8], (other[0] - px, other[1] - py), atol=1e-4)


def test_path_batch_matches_single_paths() -> None:
    paths = [Scenario.preset(curvature=k).path for k in (0.003, 0.0, -0.004, 1e-9)]
    batch = PathBatch.of(paths[0], len(paths))
    for i, p in enumerate(paths):
        batch.set(i, p)
    rng = np.random.default_rng(2)
    x, y = rng.uniform(-30.0, 60.0, len(paths)), rng.uniform(-20.0, 30.0, len(paths))
    lam = project(batch, x, y)
    np.testing.assert_allclose(lam, [project(p, xi, yi) for p, xi, yi in zip(paths, x, y)], rtol=1e-12)
    batch_point = np.stack(point(batch, lam), axis=-1)
    single = [point(p, li) for p, li in zip(paths, lam)]
    np.testing.assert_allclose(batch_point, np.array(single, dtype=float), rtol=1e-12, atol=1e-12)
