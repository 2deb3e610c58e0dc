"""The observation layout: its sizes, slots and flags, and the accessors agents read it with."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from risk_env import ENV_ID, observation
from risk_env.models.ops import NUMPY


def test_sizes_and_slots():
    assert [observation.size(k) for k in (1, 2, 5)] == [16, 22, 40] and observation.SIZE == 16
    assert [observation.slot_count(n) for n in (16, 22, 40)] == [1, 2, 5]
    for bad in (10, 15, 17, 21):
        with pytest.raises(ValueError, match="10 \\+ 6 K entries"):
            observation.slot_count(bad)
    assert observation.slot(1) == slice(16, 22)
    assert observation.slices(2)["present"] == slice(10, 22, 6)
    assert observation.OBJECT == slice(11, 16) and observation.PRESENT == 10


def test_the_env_fills_slots_in_scenario_order_and_flags_the_rest_absent():
    env = gym.make(ENV_ID, scene="two_crossing", object_slots=4).unwrapped
    obs, info = env.reset(seed=0)
    assert obs.shape == (observation.size(4),) and env.observation_space.contains(obs)
    parts = observation.split(obs, slots=4)
    assert parts.present.tolist() == [True, True, False, False] and parts.slots == 4
    assert np.all(obs[observation.EGO_SIZE + 12 :] == 0.0)  # absent slots: all zeros
    np.testing.assert_allclose(parts.objects[:2, :2], info["objects"][:, :2], rtol=1e-6)
    np.testing.assert_allclose(parts.objects[:2], env.object_measurements, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(parts.object_measurement, parts.objects[0])
    np.testing.assert_array_equal(parts.measurements, parts.objects[:2])
    # the same observation from its parts
    rebuilt = observation.build(
        parts.ego_pose, parts.ego_input, parts.progress, parts.path_error, env.object_measurements, slots=4
    )
    np.testing.assert_array_equal(rebuilt, obs)


def test_build_wraps_headings_and_refuses_to_drop_objects():
    obs = observation.build(
        (1.0, 2.0, 7.0), (3.0, 0.1), -5.0, (0.1, 0.2, 0.3, 0.4), [(4.0, 5.0, -4.0, 2.0, 0.0)]
    )
    assert obs.dtype == np.float32 and obs.shape == (16,)
    assert obs[2] == np.float32(NUMPY.wrap_angle(7.0)) and obs[13] == np.float32(NUMPY.wrap_angle(-4.0))
    assert obs[observation.PRESENT] == 1.0 and obs[observation.PROGRESS] == -5.0
    with pytest.raises(ValueError, match="2 objects do not fit 1 slot"):
        observation.build((0, 0, 0), (0, 0), 0.0, (0, 0, 0, 0), np.zeros((2, 5)), slots=1)


def test_split_rejects_what_no_env_gives():
    good = observation.build((0, 0, 0), (0, 0), 0.0, (0, 0, 0, 0), [(1, 2, 0, 1, 0)], slots=2)
    assert observation.split(good).present.tolist() == [True, False]
    with pytest.raises(ValueError, match=r"has 2 object slot\(s\) \(22 entries\), expected 3 \(28 entries\)"):
        observation.split(good, slots=3)
    flag = good.copy()
    flag[observation.slot(1).start] = 0.5
    with pytest.raises(ValueError, match="flags must be 1.0 .* or 0.0"):
        observation.split(flag)
    ghost = good.copy()
    ghost[observation.slot(1).start + 1] = 3.0
    with pytest.raises(ValueError, match=r"slot\(s\) \[1\] are marked absent but hold nonzero entries"):
        observation.split(ghost)
    nan = good.copy()
    nan[0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        observation.split(nan)
    with pytest.raises(ValueError, match="one vector"):
        observation.split(np.stack([good, good]))
    none = observation.build((0, 0, 0), (0, 0), 0.0, (0, 0, 0, 0), np.zeros((0, 5)), slots=2)
    with pytest.raises(ValueError, match="holds no object: all 2 slot"):
        observation.split(none).object_measurement  # noqa: B018


def test_bounds_hold_flags_in_zero_one():
    low, high = observation.bounds(3)
    flags = observation.slices(3)["present"]
    assert np.all(low[flags] == 0.0) and np.all(high[flags] == 1.0)
    heads = [2, 8, *(observation.slot(i).start + 3 for i in range(3))]
    assert set(np.flatnonzero(high == np.float32(np.pi))) == set(heads)
    assert np.all(low[: observation.EGO_SIZE] == -high[: observation.EGO_SIZE])
