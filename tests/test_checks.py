"""Strict input checks (issue 14, item 4): every listed bad input gets an error naming it, every
listed valid one passes. One test per case of the issue, plus the helpers of risk_env.checks."""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import risk_env  # noqa: F401  (registers RiskCrossing-v0)
from agents.base import as_batch
from risk_env import ENV_ID, Scenario, Variations, checks, observation
from risk_env.envs.env import RiskCrossingEnv


def make(**kwargs) -> RiskCrossingEnv:
    return gym.make(ENV_ID, **kwargs).unwrapped


def started(**kwargs) -> RiskCrossingEnv:
    env = make(**kwargs)
    env.reset(seed=0)
    return env


def vec(num_envs: int = 3, **kwargs) -> gym.vector.VectorEnv:
    env = gym.make_vec(ENV_ID, num_envs=num_envs, **kwargs)
    env.reset(seed=0)
    return env


# ---------------------------------------------------------------- actions: single env
BAD_ACTIONS = [
    (["1", "0"], r"action must be 2 numbers .*\['1', '0'\].* with strings"),
    ([True, False], r"action must be 2 numbers .*\[True, False\].* with bools"),
    (np.array([True, False]), r"action .*array\(\[ True, False\]\).* with bools"),
    ([np.True_, 0.5], r"action .* with bools"),
    (np.array([1 + 1j, 0]), r"action .*1\.\+1\.j.* with complex numbers"),
    ([1 + 0j, 0.0], r"action .*\(1\+0j\).* with complex numbers"),
    (np.array([1.0, None]), r"action .*None.* dtype object"),
    ([[1.0], 0.0], r"action must be 2 numbers .*\[\[1\.0\], 0\.0\]"),
    ("10", r"action .*'10'.* with strings"),
]


@pytest.mark.parametrize(("action", "message"), BAD_ACTIONS)
def test_non_real_actions_are_rejected_by_name(action, message):
    env = started()
    before = env.object_measurement
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no ComplexWarning on the way
        with pytest.raises(ValueError, match=message):
            env.step(action)
    np.testing.assert_array_equal(env.object_measurement, before)
    assert env.steps == 0


@pytest.mark.parametrize(
    "action",
    [
        np.array([3.0, 0.1], dtype=np.float32),
        np.array([3.0, 0.1], dtype=np.float64),
        np.array([3.0, 0.1], dtype=np.float16),
        np.array([3, 0], dtype=np.int64),
        np.array([3, 0], dtype=np.uint8),
        [3.0, 0.1],
        (3, 0),
        [np.float32(3.0), np.int64(0)],
    ],
    ids=["float32", "float64", "float16", "int64", "uint8", "list", "tuple", "numpy scalars"],
)
def test_real_actions_of_every_numeric_type_are_accepted_alike(action):
    env, reference = started(), started()
    expected = reference.step(np.asarray(action, dtype=float))[0]
    np.testing.assert_array_equal(env.step(action)[0], expected)


def test_an_action_at_the_float32_bounds_passes_for_any_limit():
    # float32(32.24) > 32.24 by 1.7e-6: the Box's own corner must still be an action
    env = started(v_max=32.24, v_ref=4.0)
    assert float(env.action_space.high[0]) > 32.24 + 1e-6
    env.step(env.action_space.high)
    env.step(env.action_space.low)
    with pytest.raises(ValueError, match="outside"):
        env.step(np.array([32.25, 0.0]))


# ---------------------------------------------------------------- actions: batched env
@pytest.mark.parametrize(
    ("actions", "message"),
    [
        ([["1", "0"]] * 3, r"actions must be numbers of shape \(3, 2\).* with strings"),
        ([[True, False]] * 3, r"actions .* with bools"),
        ([[4.0, 0.0], [4.0, 0.0], [True, 0.5]], r"actions .* with bools"),
        (np.zeros((3, 2), dtype=complex), r"actions .* with complex numbers"),
        (np.full((3, 2), np.nan), r"actions of copies \[0, 1, 2\] are non-finite"),
    ],
)
def test_batched_env_rejects_non_real_actions(actions, message):
    env = vec()
    with pytest.raises(ValueError, match=message):
        env.step(actions)


def test_batched_env_accepts_real_actions_of_every_numeric_type():
    ref = vec()
    expected = ref.step(np.full((3, 2), [3.0, 0.0]))[0]
    for actions in (
        np.full((3, 2), [3.0, 0.0], dtype=np.float32),
        np.full((3, 2), [3, 0], dtype=np.int32),
        [[3.0, 0.0]] * 3,
        [(3, 0)] * 3,
    ):
        np.testing.assert_array_equal(vec().step(actions)[0], expected)


# ---------------------------------------------------------------- actions: RiskCostWrapper
@pytest.fixture(scope="module")
def highway_envs():
    pytest.importorskip("highway_env")
    from risk_env.highway import RiskCostWrapper

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        continuous = gym.make(
            "intersection-v1", config={"action": {"type": "ContinuousAction", "dynamical": False}}
        )
        discrete = gym.make("highway-fast-v0")
    return RiskCostWrapper(continuous), RiskCostWrapper(discrete)


BAD_BOX_ACTIONS = [
    (np.array([np.nan, 0.0]), r"action must be finite, got array\(\[nan, +0\.\]\)"),
    ([0.1, math.inf], r"action must be finite, got \[0\.1, inf\]"),
    (["1", "0"], r"action .*\['1', '0'\].* with strings"),
    ([True, False], r"action .* with bools"),
    (np.array([0.1, 0.2, 0.3]), r"action must have shape \(2,\), got shape \(3,\)"),
]
BAD_DISCRETE_ACTIONS = [
    (7, ValueError, r"action must be an integer in \[0, 5\), got 7"),
    (True, TypeError, "action must be an integer, got the bool True"),
    (1.0, TypeError, r"action must be an integer .*1\.0 \(float\)"),
    ("1", TypeError, r"action must be an integer .*'1' \(str\)"),
    (np.array([0.1, 0.0]), TypeError, "action must be an integer"),
]


@pytest.mark.parametrize(("action", "message"), BAD_BOX_ACTIONS)
def test_risk_cost_wrapper_checks_box_actions_before_highway_env(highway_envs, action, message):
    wrapper = highway_envs[0]
    wrapper.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        wrapper.step(action)


@pytest.mark.parametrize(("action", "error", "message"), BAD_DISCRETE_ACTIONS)
def test_risk_cost_wrapper_checks_discrete_actions(highway_envs, action, error, message):
    wrapper = highway_envs[1]
    wrapper.reset(seed=0)
    with pytest.raises(error, match=message):
        wrapper.step(action)


def test_risk_cost_wrapper_takes_valid_actions_after_refusing_bad_ones(highway_envs):
    """Every bad action above refused, one after the other, and then the valid ones pass."""
    continuous, discrete = highway_envs
    continuous.reset(seed=0)
    for action, message in BAD_BOX_ACTIONS:
        with pytest.raises(ValueError, match=message):
            continuous.step(action)
    continuous.step(np.array([0.1, 0.0], dtype=np.float32))
    continuous.step([0, 0.0])
    discrete.reset(seed=0)
    for action, error, message in BAD_DISCRETE_ACTIONS:
        with pytest.raises(error, match=message):
            discrete.step(action)
    for valid in (1, np.int64(2), np.array(3), None):  # None: highway-env's "no new action"
        discrete.step(valid)


# ---------------------------------------------------------------- scenario fields
@pytest.mark.parametrize(
    ("overrides", "error", "message"),
    [
        ({"risk_tolerance": "500"}, TypeError, r"risk_tolerance must be a real number .*'500' \(str\)"),
        ({"risk_tolerance": True}, TypeError, r"risk_tolerance must be a real number .*True \(bool\)"),
        ({"ego_mass": "1000"}, TypeError, r"ego\.mass must be a real number .*'1000' \(str\)"),
        ({"object_speed": None}, TypeError, r"object\.speed must be a real number .*None \(NoneType\)"),
        ({"ego_start": "abc"}, TypeError, r"ego\.start must be a sequence of 3 real numbers, got 'abc'"),
        ({"uncertainty": ["low"]}, TypeError, r"uncertainty preset must be a string.*\['low'\] \(list\)"),
        ({"horizon": True}, TypeError, "horizon must be an integer, got the bool True"),
        ({"horizon": 4.5}, TypeError, r"horizon must be an integer .*4\.5 \(float\)"),
        ({"horizon": 4.0}, TypeError, r"horizon must be an integer .*4\.0 \(float\)"),
        ({"max_steps": np.float64(20)}, TypeError, "max_steps must be an integer"),
        ({"max_steps": np.True_}, TypeError, "max_steps must be an integer, got the bool"),
        ({"horizon": np.int64(0)}, ValueError, r"horizon must be an integer >= 1, got np\.int64\(0\)"),
    ],
)
def test_listed_scenario_values_are_rejected_by_name(overrides, error, message):
    with pytest.raises(error, match=message):
        gym.make(ENV_ID, **overrides)
    if "uncertainty" not in overrides:
        with pytest.raises(error, match=message):
            Scenario.preset("low", **overrides)


@pytest.mark.parametrize(
    "overrides",
    [
        {"horizon": np.int64(4)},
        {"horizon": np.int32(4), "max_steps": np.int64(20)},
        {"max_steps": np.uint16(20), "mc_samples": np.int8(50), "grid_points": np.int64(10)},
        {"risk_tolerance": np.float32(500.0), "ego_mass": np.int64(1000), "v_ref": np.float64(3.0)},
        {"ego_start": np.array([-10.0, 10.0, 0.0]), "object_start": [np.int64(5), -5, np.float32(1.5)]},
        {"risk_tolerance": 500, "object_speed": 2},
    ],
)
def test_integral_and_real_types_of_numpy_are_accepted(overrides):
    env = make(**overrides)
    s = env.scenario
    assert type(s.horizon) is int and type(s.max_steps) is int  # stored as Python numbers
    assert type(s.risk_tolerance) is float and type(s.ego.mass) is float
    assert all(type(v) is float for v in s.ego.start.as_tuple())
    if "horizon" in overrides:
        assert s.horizon == 4


def test_make_vec_takes_numpy_integers_for_num_envs():
    env = gym.make_vec(ENV_ID, num_envs=np.int64(4))
    assert env.num_envs == 4 and type(env.num_envs) is int
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4, observation.SIZE)
    for bad, error in ((True, TypeError), (2.0, TypeError), ("4", TypeError), (0, ValueError)):
        with pytest.raises(error, match="num_envs must be an integer"):
            gym.make_vec(ENV_ID, num_envs=bad)


def test_env_arguments_reject_wrong_types():
    with pytest.raises(TypeError, match=r"reward_risk_weight must be a real number .*'1' \(str\)"):
        make(reward_risk_weight="1")
    with pytest.raises(TypeError, match=r"randomize must be True or False, got 'yes' \(str\)"):
        make(randomize="yes")
    with pytest.raises(TypeError, match=r"Variations\.curvature must be a real number .*'0\.1' \(str\)"):
        Variations(curvature="0.1")


# ---------------------------------------------------------------- scenario vs observation bounds
@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"object_turn_rate": 2000.0}, r"object turn rate can reach 2000 rad/s .* change object\.turn_rate"),
        (
            {"object_speed": 1500.0, "velocity_bounds0": (-2000.0, 2000.0)},
            r"object speed can reach 2001 m/s .*bound 1000 m/s; change object\.speed",
        ),
        (
            {"ego_start": (2e5, 0.0, 0.0)},
            r"ego position can reach 200320 m .*bound 100000 m; change ego\.start",
        ),
        ({"velocity_bounds0": (-999.5, 999.5)}, "object speed can reach 1000.5 m/s"),
        ({"max_steps": 10**6}, r"ego position can reach 4\.00001e\+06 m .*max_steps = 1000000"),
    ],
)
def test_scenarios_whose_observations_leave_the_box_are_rejected(overrides, message):
    with pytest.raises(ValueError, match=message):
        gym.make(ENV_ID, **overrides)


def test_a_scenario_at_the_observation_bounds_stays_in_the_box():
    # everything as large as the scenario accepts; bang-bang actions at the Box's corners
    v = 499.0
    env = make(
        ego_start=(-9.9e4 + 2.0, 0.0, 0.0),
        goal=(-9.9e4 + 5.0, 0.0, 0.0),
        curvature=0.0,
        v_min=-v,
        v_max=v,
        v_ref=0.0,
        omega_max=999.0,
        object_start=(0.0, 9.8e4, 0.0),
        object_speed=990.0,
        object_turn_rate=-999.9,
        velocity_bounds0=(-996.0, 996.0),
        box_growth=(3.0, 3.0, 3.0),
        max_steps=2,
        dt=0.5,
        object_motion="sampled",
    )
    reach = env.scenario.observation_reach()
    assert all(value <= bound for value, bound, _, _ in reach.values())
    assert reach["object speed"][0] == 999.0
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    for action in (env.action_space.low, env.action_space.high):
        obs, *_ = env.step(action)
        assert env.observation_space.contains(obs), obs


def test_observation_bounds_live_in_the_observation_module():
    low, high = observation.bounds()
    box = make().observation_space
    np.testing.assert_array_equal(box.high, high)
    np.testing.assert_array_equal(box.low, low)
    assert high[observation.PROGRESS] == observation.POSITION_BOUND
    assert set(np.flatnonzero(high == np.float32(np.pi))) == set(observation.HEADINGS)
    assert (low[observation.PRESENT], high[observation.PRESENT]) == (0.0, 1.0)  # the flag
    flags = np.zeros(observation.SIZE, dtype=bool)
    flags[observation.PRESENT] = True
    np.testing.assert_array_equal(low[~flags], -high[~flags])
    low3, high3 = observation.bounds(3)
    box3 = make(object_slots=3).observation_space
    np.testing.assert_array_equal(box3.low, low3)
    np.testing.assert_array_equal(high3[observation.slot(2)], high[observation.slot(0)])


# ---------------------------------------------------------------- stepping past the end
def truncated_env(**kwargs) -> gym.Env:
    # the object far away: nothing ends the episode but max_steps
    return gym.make(ENV_ID, max_steps=3, object_start=(60.0, 60.0, 0.0), object_speed=0.0, **kwargs)


def test_stepping_after_truncation_raises_until_reset():
    env = truncated_env()
    env.reset(seed=0)
    action = np.array([2.0, 0.0], dtype=np.float32)
    for k in range(3):
        *_, terminated, truncated, _ = env.step(action)
        assert not terminated and truncated == (k == 2)
    with pytest.raises(gym.error.ResetNeeded, match=r"the episode has ended \(truncated at max_steps = 3\)"):
        env.step(action)
    with pytest.raises(gym.error.ResetNeeded):  # and again, until reset
        env.step(action)
    env.reset()
    env.step(action)


def test_stepping_after_a_collision_raises_and_the_state_stays():
    env = make(object_start=(-6.5, 10.0, 0.0), object_speed=0.0)
    env.reset(seed=0)
    *_, terminated, _, info = env.step(np.array([2.0, 0.0]))
    assert terminated and info["collision"]
    before = env.object_measurement
    with pytest.raises(gym.error.ResetNeeded, match="terminated by a collision at step 1"):
        env.step(np.array([2.0, 0.0]))
    np.testing.assert_array_equal(env.object_measurement, before)
    env.reset(seed=0)
    assert env.steps == 0


def test_stepping_after_the_goal_raises():
    env = make(ego_start=(64.0, 5.0, 0.0))
    env.reset(seed=0)
    *_, terminated, _, info = env.step(np.array([4.0, 0.0]))
    assert terminated and info["is_success"]
    with pytest.raises(gym.error.ResetNeeded, match="terminated at the goal at step 1"):
        env.step(np.array([4.0, 0.0]))


def test_the_final_frame_still_renders_after_the_end():
    env = gym.make(ENV_ID, max_steps=1, render_mode="rgb_array", renderer="basic")
    env.reset(seed=0)
    env.step(np.array([1.0, 0.0]))
    frame = env.render()
    assert frame.ndim == 3
    env.close()


def test_gymnasium_wrappers_pass_the_error_through():
    # TimeLimit ending earlier than max_steps: its truncation, then the next episode runs as usual.
    env = truncated_env(max_episode_steps=2)
    assert isinstance(env, gym.wrappers.TimeLimit)
    env.reset(seed=0)
    env.step(np.array([1.0, 0.0]))
    assert env.step(np.array([1.0, 0.0]))[3]
    env.reset()
    # TimeLimit later than max_steps: the env's own end comes first and its error passes the
    # wrappers (TimeLimit, OrderEnforcing, PassiveEnvChecker) unchanged.
    env = truncated_env(max_episode_steps=10)
    env.reset(seed=0)
    for _ in range(3):
        truncated = env.step(np.array([1.0, 0.0]))[3]
    assert truncated
    with pytest.raises(gym.error.ResetNeeded, match="the episode has ended"):
        env.step(np.array([1.0, 0.0]))


def test_gymnasiums_sync_vector_env_and_autoreset_wrapper_step_on():
    # They reset an ended env themselves: no error.
    sync = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync", max_steps=2)
    sync.reset(seed=0)
    for _ in range(5):
        sync.step(np.full((2, 2), [1.0, 0.0]))
    auto = gym.wrappers.Autoreset(gym.make(ENV_ID, max_steps=2))
    auto.reset(seed=0)
    for _ in range(5):
        auto.step(np.array([1.0, 0.0]))


def test_the_batched_env_autoresets_instead_of_raising():
    for mode in ("next_step", "same_step"):
        env = vec(2, max_steps=2, autoreset_mode=mode)
        ends = 0
        for _ in range(7):
            _, _, _, truncated, _ = env.step(np.full((2, 2), [1.0, 0.0]))
            ends += int(truncated.sum())
        assert ends >= 4


# ---------------------------------------------------------------- agents: empty batch
def test_as_batch_rejects_an_empty_batch_and_non_real_observations():
    with pytest.raises(ValueError, match=r"observation is an empty batch, shape \(0, 15\)"):
        as_batch(np.zeros((0, 15)), 15)
    with pytest.raises(ValueError, match=r"observation .* with strings"):
        as_batch(["0"] * 15, 15)
    with pytest.raises(ValueError, match=r"observation .* with bools"):
        as_batch(np.zeros(15, dtype=bool), 15)
    obs, single = as_batch(np.zeros(15, dtype=np.float32), 15)
    assert single and obs.shape == (1, 15) and obs.dtype == np.float64
    obs, single = as_batch(np.zeros((2, 15), dtype=np.int64), 15)
    assert not single and obs.shape == (2, 15) and obs.dtype == np.float64


def test_an_observation_with_other_object_slots_is_named_so():
    with pytest.raises(
        ValueError, match=r"got \(22,\) \(an observation with 2 object slot\(s\); this agent reads 1\)"
    ):
        as_batch(np.zeros(22), observation.SIZE)
    with pytest.raises(
        ValueError, match=r"got \(3, 16\) \(an observation with 1 object slot\(s\); this agent reads 2\)"
    ):
        as_batch(np.zeros((3, 16)), observation.size(2))
    with pytest.raises(ValueError, match=r"got \(15,\)$"):  # no observation of ours: no hint
        as_batch(np.zeros(15), observation.SIZE)


@pytest.mark.parametrize("agent_name", ["RMPC", "SMPC"])
def test_agents_reject_an_empty_batch_by_name(agent_name):
    import agents

    agent = getattr(agents, agent_name)(Scenario.preset("low", horizon=3), max_solve_time=math.inf)
    with pytest.raises(ValueError, match=r"observation is an empty batch, shape \(0, 16\)"):
        agent.predict(np.zeros((0, 16)))


def test_ppo_agent_rejects_an_empty_batch():
    pytest.importorskip("stable_baselines3")
    import agents
    from agents import PPOAgent

    agent = PPOAgent.load(Path(agents.__file__).parent / "models" / "ppo_penalty.zip")
    with pytest.raises(ValueError, match="empty batch"):
        agent.predict(np.zeros((0, 16), dtype=np.float32))


# ---------------------------------------------------------------- the helpers
def test_real_and_integer_helpers():
    assert checks.real("x", np.float32(0.5)) == 0.5 and checks.real("x", np.int64(3)) == 3.0
    assert checks.real("x", np.array(2.5)) == 2.5
    for bad in ("1", True, np.True_, None, 1j, [1.0], np.array([1.0])):
        expected = re.escape(f"x must be a real number (int or float), got {checks.describe(bad)}")
        with pytest.raises(TypeError, match=expected):
            checks.real("x", bad)
    with pytest.raises(ValueError, match="x must be finite"):
        checks.real("x", 10**400)
    assert checks.integer("n", np.uint8(7)) == 7 and checks.integer("n", np.array(7)) == 7
    for bad in (7.0, "7", None, np.float32(7)):
        with pytest.raises(TypeError, match="n must be an integer"):
            checks.integer("n", bad)
    with pytest.raises(ValueError, match="n must be an integer >= 2, got 1"):
        checks.integer("n", 1, minimum=2)


def test_text_and_reals_helpers():
    assert checks.text("severity", "paper", ("paper", "plastic")) == "paper"
    with pytest.raises(ValueError, match=r"unknown severity 'papr' \(did you mean 'paper'\?\)"):
        checks.text("severity", "papr", ("paper", "plastic"))
    with pytest.raises(TypeError, match=r"severity must be a string.*\['paper'\] \(list\)"):
        checks.text("severity", ["paper"], ("paper", "plastic"))
    assert checks.reals("p", np.array([1, 2, 3]), 3) == (1.0, 2.0, 3.0)
    with pytest.raises(TypeError, match=r"p\[1\] must be a real number .*'2' \(str\)"):
        checks.reals("p", (1, "2", 3), 3)
    with pytest.raises(TypeError, match="p must be a sequence of 3 real numbers"):
        checks.reals("p", {"x": 1, "y": 2, "z": 3}, 3)
    with pytest.raises(TypeError, match="p must be a sequence of 3 real numbers"):
        checks.reals("p", np.zeros((3, 1)), 3)
    with pytest.raises(ValueError, match="p must have 3 entries, got 2"):
        checks.reals("p", (1, 2), 3)


def test_space_action_for_tuple_spaces():
    space = spaces.Tuple((spaces.Discrete(3), spaces.Box(-1.0, 1.0, (2,))))
    checks.space_action((np.int64(2), [0.5, -0.5]), space)
    with pytest.raises(ValueError, match=r"action\[1\] must be finite"):
        checks.space_action((0, [np.nan, 0.0]), space)
    with pytest.raises(ValueError, match="action must be a tuple of 2 actions"):
        checks.space_action((0,), space)
    with pytest.raises(ValueError, match="not in the action space"):
        checks.space_action(np.array([2, 1]), spaces.MultiBinary(2))


# ---------------------------------------------------------------- seeds and indices
def test_seeds_take_integral_types_and_name_bad_ones():
    single, batched = make(), gym.make_vec(ENV_ID, num_envs=2)
    a, _ = single.reset(seed=np.int64(3))
    np.testing.assert_array_equal(a, single.reset(seed=3)[0])
    b, _ = batched.reset(seed=np.int64(3))
    np.testing.assert_array_equal(b, batched.reset(seed=[3, 4])[0])
    batched.reset(seed=[np.uint32(1), None])
    for env in (single, batched):
        with pytest.raises(TypeError, match=r"seed must be an integer .*2\.5 \(float\)"):
            env.reset(seed=2.5)
        with pytest.raises(ValueError, match="seed must be an integer >= 0, got -1"):
            env.reset(seed=-1)
    with pytest.raises(TypeError, match=r"seed\[1\] must be an integer .*'4' \(str\)"):
        batched.reset(seed=[3, "4"])
    with pytest.raises(ValueError, match="seed must be None, an int or a list of 2 seeds, got 3"):
        batched.reset(seed=[1, 2, 3])


def test_risk_cost_wrapper_vehicle_index_takes_integral_types(highway_envs):
    from risk_env.highway import RiskCostWrapper

    env = highway_envs[1].env
    assert RiskCostWrapper(env, vehicle_index=np.int64(0)).vehicle_index == 0
    with pytest.raises(TypeError, match=r"vehicle_index must be an integer .*0\.0 \(float\)"):
        RiskCostWrapper(env, vehicle_index=0.0)
    with pytest.raises(ValueError, match="vehicle_index must be an integer >= 0, got -1"):
        RiskCostWrapper(env, vehicle_index=-1)
