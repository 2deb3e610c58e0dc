"""RiskCrossing-v0: Gymnasium's checker, the step sequence, the info it reports and its errors."""

from __future__ import annotations

import copy
import importlib
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import risk_env
from risk_env import ENV_ID, ESTIMATOR_NAMES, RiskCrossingEnv, Scenario, observation, predict
from risk_env.models import dynamics
from risk_env.models.path import point
from risk_env.risk.estimators import MonteCarloRisk, make_estimator

# The action Box is in physical units on purpose; Gymnasium's checker advises a normalised one.
_NORMALISED_SPACE_ADVICE = r".*symmetric and normalized space.*"


def make(**kwargs) -> RiskCrossingEnv:
    return gym.make(ENV_ID, **kwargs).unwrapped


def act(v: float, omega: float = 0.0) -> np.ndarray:
    return np.array([v, omega], dtype=np.float32)


def near_object_env(**kwargs) -> RiskCrossingEnv:
    """The object starts beside the ego's line so that after one step at 4 m/s the centres are
    sqrt(10) m apart, just outside r_e + r_o = 3 m: a clearly nonzero, sub-certain risk."""
    return make(object_start=(-5.0, 7.5, math.pi / 2), **kwargs)


def checked(env: gym.Env) -> None:
    """check_env with every warning an error, except the advice on normalised action spaces."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=_NORMALISED_SPACE_ADVICE)
        check_env(env)


# ---------------------------------------------------------------- Gymnasium's checker
def test_check_env_default_with_every_render_mode():
    # A spec'd env with render_mode=None: the checker also builds one env per declared render mode.
    checked(gym.make(ENV_ID).unwrapped)


@pytest.mark.parametrize("estimator", ESTIMATOR_NAMES)
def test_check_env_each_estimator_with_rgb_array(estimator):
    checked(gym.make(ENV_ID, risk_estimator=estimator, render_mode="rgb_array").unwrapped)


def test_check_env_sampled_motion_with_monte_carlo():
    # Both the motion and the estimator draw from np_random: the determinism checks must hold.
    checked(gym.make(ENV_ID, object_motion="sampled", risk_estimator="monte_carlo").unwrapped)


# ---------------------------------------------------------------- registration
def test_import_twice_registers_once_without_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        importlib.reload(risk_env)
        importlib.reload(risk_env)
    assert ENV_ID in gym.registry
    assert gym.registry[ENV_ID].entry_point == "risk_env.envs.env:RiskCrossingEnv"
    env = gym.make(ENV_ID)
    assert isinstance(env.unwrapped, risk_env.RiskCrossingEnv)


# ---------------------------------------------------------------- construction
def test_overrides_reach_the_scenario_and_the_spaces():
    env = make(
        uncertainty="medium",
        risk_tolerance=500.0,
        object_start=(1.0, -2.0, 1.0),
        object_speed=2.5,
        v_ref=3.0,
        severity="plastic",
        v_min=-1.0,
        v_max=6.0,
        omega_max=0.5,
        dt=0.25,
    )
    s = env.scenario
    assert s.uncertainty == Scenario.preset("medium").uncertainty
    assert env.epsilon == s.risk_tolerance == 500.0
    assert s.object.start.as_tuple() == (1.0, -2.0, 1.0)
    assert s.object.speed == 2.5
    assert s.ego.v_ref == 3.0
    assert s.severity == "plastic" and env.estimator.severity.name == "plastic"
    np.testing.assert_array_equal(env.action_space.low, np.float32([-1.0, -0.5]))
    np.testing.assert_array_equal(env.action_space.high, np.float32([6.0, 0.5]))
    assert env.metadata["render_fps"] == pytest.approx(4.0)
    obs, info = env.reset(seed=0)
    np.testing.assert_array_equal(info["object"], [1.0, -2.0, 1.0, 2.5])
    assert obs[observation.OBJECT_INPUT][0] == np.float32(2.5)
    assert info["path_error"][3] == pytest.approx(0.0 - 3.0)  # at rest, v_ref = 3


def test_defaults_are_the_papers_low_preset():
    env = make()
    assert env.scenario == Scenario.preset("low")
    assert env.epsilon == 0.0
    assert env.estimator.name == "exact"
    assert env.object_motion == "paper"
    assert env.metadata["render_fps"] == pytest.approx(2.0)
    assert env.observation_slices == observation.SLICES and env.object_slots == 1
    assert env.observation_space.shape == (observation.SIZE,) == (16,)
    assert env.observation_space.dtype == np.float32
    assert np.all(np.isfinite(env.observation_space.low))


def test_scenario_argument(short_scenario):
    env = make(scenario=short_scenario, risk_estimator="worst_case")
    assert env.scenario is short_scenario
    _, info = env.reset(seed=0)
    np.testing.assert_array_equal(info["ego"][:3], short_scenario.ego.start.as_tuple())
    for extra in ({"uncertainty": "low"}, {"risk_tolerance": 500.0}, {"v_ref": 3.0}):
        with pytest.raises(TypeError, match=f"not both.*{next(iter(extra))}"):
            make(scenario=short_scenario, **extra)
    with pytest.raises(TypeError, match="must be a risk_env.Scenario"):
        make(scenario={"horizon": 3})


# ---------------------------------------------------------------- bad input
def test_unknown_keyword_names_it_with_a_suggestion():
    with pytest.raises(TypeError, match=r"'objekt_speed'.*did you mean object_speed"):
        make(objekt_speed=2.0)
    with pytest.raises(TypeError, match=r"'risk_estimater'.*did you mean risk_estimator"):
        make(risk_estimater="exact")


def test_unknown_names_raise():
    with pytest.raises(ValueError, match="'extreme'"):
        make(uncertainty="extreme")
    with pytest.raises(ValueError, match="unknown risk estimator 'bayes'"):
        make(risk_estimator="bayes")
    with pytest.raises(ValueError, match="unknown object_motion 'teleport'"):
        make(object_motion="teleport")
    with pytest.raises(ValueError, match="reward_risk_weight"):
        make(reward_risk_weight=-1.0)
    with pytest.raises(ValueError, match="render_mode 'ascii'"):
        RiskCrossingEnv(render_mode="ascii")


@pytest.mark.parametrize(
    ("action", "message"),
    [
        (np.array([np.nan, 0.0]), "finite"),
        (np.array([1.0, np.inf]), "finite"),
        (np.zeros(3), r"shape \(2,\).*\(3,\)"),
        (np.zeros((1, 2)), r"shape \(2,\).*\(1, 2\)"),
        (["fast", "left"], "2 numbers"),
        (np.array([9.0, 0.0]), r"v = 9.0 m/s lies outside \[v_min, v_max\] = \[-4.0, 8.0\]"),
        (np.array([-4.1, 0.0]), r"v = -4.1 m/s"),
        (np.array([1.0, -0.81]), r"omega = -0.81 rad/s lies outside .*\[-0.8, 0.8\]"),
        (np.array([8.0 + 1e-5, 0.0]), "lies outside"),
    ],
)
def test_bad_actions_raise_and_leave_the_state(action, message):
    env = make()
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(action)
    obs_after, *_ = env.step(act(0.0))  # nothing moved the ego before the error
    np.testing.assert_array_equal(obs_after[observation.EGO_POSE], obs[observation.EGO_POSE])


def test_action_within_tolerance_is_applied_unclipped():
    env = make()
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([8.0 + 5e-7, 0.8 + 5e-7]))
    assert info["ego"][3] == 8.0 + 5e-7


def test_step_before_reset_and_reset_options():
    with pytest.raises(gym.error.ResetNeeded):
        make().step(act(0.0))
    with pytest.raises(gym.error.ResetNeeded):
        gym.make(ENV_ID).step(act(0.0))
    env = make()
    env.reset(options=None)
    env.reset(options={})
    with pytest.raises(ValueError, match="no reset options.*'warp'"):
        env.reset(options={"warp": 1})


# ---------------------------------------------------------------- info
_INFO_TYPES = {
    "risk": float,
    "cost": float,
    "episode_risk": float,
    "risk_violation": bool,
    "collision": bool,
    "distance": float,
    "closest_object": int,
    "risk_terms": np.ndarray,
    "objects": np.ndarray,
    "present": np.ndarray,
    "path_error": np.ndarray,
    "lambda": float,
    "ego": np.ndarray,
    "object": np.ndarray,
    "rewards": dict,
    "is_success": bool,
}


def test_info_keys_and_types_at_reset_and_step():
    env = make()
    obs, reset_info = env.reset(seed=0)
    obs1, reward, terminated, truncated, step_info = env.step(act(2.0, 0.1))
    for info in (reset_info, step_info):
        assert set(info) == set(_INFO_TYPES)
        for key, kind in _INFO_TYPES.items():
            assert type(info[key]) is kind, key
        assert info["path_error"].shape == (4,) and info["ego"].shape == (4,)
        assert info["object"].shape == (4,) and info["objects"].shape == (1, 4)
        assert info["risk_terms"].shape == (1,) and info["risk_terms"][0] == info["risk"]
        assert info["present"].tolist() == [True] and info["closest_object"] == 0
        assert set(info["rewards"]) == {"path_error", "risk"}
    assert reset_info["risk"] == 0.0 and reset_info["rewards"] == {"path_error": 0.0, "risk": 0.0}
    assert type(reward) is float and type(terminated) is bool and type(truncated) is bool
    assert obs1.dtype == np.float32 and obs1.shape == (16,)


def test_observation_matches_info():
    env = make()
    env.reset(seed=0)
    for _ in range(3):
        obs, _, _, _, info = env.step(act(3.0, 0.3))
    parts = observation.split(obs)
    theta = (info["ego"][2] + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(parts.ego_pose, [*info["ego"][:2], theta], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(parts.ego_input, [3.0, 0.3], rtol=1e-6)
    np.testing.assert_allclose(parts.object_pose[:2], info["object"][:2], rtol=1e-6)
    assert parts.object_input[0] == pytest.approx(info["object"][3])
    assert parts.object_input[1] == pytest.approx(env.scenario.object.turn_rate)
    assert parts.progress == pytest.approx(info["lambda"], rel=1e-6)
    np.testing.assert_allclose(parts.path_error, info["path_error"], rtol=1e-5, atol=1e-6)
    assert info["distance"] == pytest.approx(np.hypot(*(info["ego"][:2] - info["object"][:2])))


def test_paper_object_follows_its_unicycle():
    env = make()
    _, info = env.reset(seed=0)
    s = env.scenario
    expected = np.array(s.object.start.as_tuple())
    for _ in range(5):
        _, _, _, _, info = env.step(act(1.0))
        expected = dynamics.step(expected, np.array([s.object.speed, s.object.turn_rate]), s.dt)
        np.testing.assert_allclose(info["object"][:3], expected, rtol=1e-12, atol=1e-12)
        assert info["object"][3] == s.object.speed


# ---------------------------------------------------------------- risk
def _belief_before(env: RiskCrossingEnv, object_before: np.ndarray):
    measurement = (*object_before, env.scenario.object.turn_rate)
    return predict(env.scenario, measurement, steps=1)[1]


def test_risk_is_the_estimator_at_the_new_state_against_the_prior_belief():
    env = near_object_env(risk_tolerance=100.0)
    _, info0 = env.reset(seed=0)
    _, _, terminated, _, info = env.step(act(4.0))
    assert not terminated and info["distance"] == pytest.approx(math.sqrt(10.0), abs=1e-3)  # omega_o = 1e-4
    belief = _belief_before(env, info0["object"])
    assert info["ego"][3] == 4.0  # the applied speed
    expected = float(make_estimator("exact", env.scenario).risk(info["ego"], belief))
    assert info["risk"] > 1.0
    assert info["risk"] == expected == info["cost"]
    assert info["risk_violation"] == (info["risk"] > 100.0)
    # ... and that number is the risk: compare with a large Monte Carlo run (independent draws).
    draws = belief.sample(np.random.default_rng(7), 400_000)
    hit = np.hypot(info["ego"][0] - draws[:, 0], info["ego"][1] - draws[:, 1]) <= 3.0
    values = hit * 0.5 * np.abs(1000.0 * 16.0 - 1000.0 * draws[:, 2] ** 2)
    stderr = values.std() / math.sqrt(len(values))
    assert abs(values.mean() - info["risk"]) < 5 * stderr


def test_monte_carlo_risk_draws_from_np_random():
    env = near_object_env(risk_estimator="monte_carlo")
    _, info0 = env.reset(seed=3)
    rng = copy.deepcopy(env.np_random)
    _, _, _, _, info = env.step(act(4.0))
    belief = _belief_before(env, info0["object"])
    expected = float(MonteCarloRisk(env.scenario).risk(info["ego"], belief, rng=rng))
    assert info["risk"] > 0.0
    assert info["risk"] == expected


@pytest.mark.parametrize("estimator", ["worst_case", "grid"])
def test_worst_case_estimators_report_their_bound(estimator):
    env = near_object_env(risk_estimator=estimator)
    _, info0 = env.reset(seed=0)
    _, _, _, _, info = env.step(act(4.0))
    belief = _belief_before(env, info0["object"])
    assert info["risk"] == float(make_estimator(estimator, env.scenario).risk(info["ego"], belief))
    exact = near_object_env()
    exact.reset(seed=0)
    assert info["risk"] >= exact.step(act(4.0))[4]["risk"] > 0.0


def test_sampled_motion_draws_inside_the_belief_and_is_seeded():
    def run(seed: int) -> tuple[list[np.ndarray], list[dict]]:
        env = make(object_motion="sampled")
        obs, info = env.reset(seed=seed)
        observations, infos = [obs], [info]
        for _ in range(8):
            obs, _, _, _, info = env.step(act(2.0, 0.05))
            observations.append(obs)
            infos.append(info)
        return observations, infos

    obs_a, info_a = run(11)
    obs_b, info_b = run(11)
    obs_c, info_c = run(12)
    for oa, ob, ia, ib in zip(obs_a, obs_b, info_a, info_b, strict=True):
        np.testing.assert_array_equal(oa, ob)
        assert ia.keys() == ib.keys() and ia["rewards"] == ib["rewards"]
        for key in ia.keys() - {"rewards"}:
            np.testing.assert_array_equal(ia[key], ib[key])
    path_a = np.array([i["object"] for i in info_a])
    path_c = np.array([i["object"] for i in info_c])
    assert not np.allclose(path_a[1:], path_c[1:])
    # Each draw lies in the truncation box of the belief made before the move, and the drawn
    # speed becomes the measured one.
    env = make(object_motion="sampled")
    for before, after, obs in zip(info_a[:-1], info_a[1:], obs_a[1:], strict=True):
        belief = _belief_before(env, before["object"])
        assert abs(after["object"][0] - belief.x) <= belief.half_x
        assert abs(after["object"][1] - belief.y) <= belief.half_y
        assert after["object"][2] == pytest.approx(float(belief.theta))
        assert belief.v_lo <= after["object"][3] <= belief.v_hi
        assert obs[observation.OBJECT_INPUT][0] == np.float32(after["object"][3])
    assert np.ptp(path_a[1:, 3]) > 0  # the speed is drawn anew each step


# ---------------------------------------------------------------- reward and episode end
def test_reward_is_minus_path_error_norm_without_weight():
    env = near_object_env()
    env.reset(seed=0)
    _, reward, _, _, info = env.step(act(4.0))
    assert info["risk"] > 0.0
    assert info["rewards"]["risk"] == 0.0
    assert reward == pytest.approx(-np.linalg.norm(info["path_error"]), rel=1e-12)


def test_reward_includes_the_weighted_risk():
    w = 1e-3
    env = near_object_env(reward_risk_weight=w)
    env.reset(seed=0)
    _, reward, _, _, info = env.step(act(4.0))
    assert info["risk"] > 1.0
    assert info["rewards"]["risk"] == pytest.approx(-w * info["risk"])
    assert reward == pytest.approx(-np.linalg.norm(info["path_error"]) - w * info["risk"], rel=1e-12)


def test_collision_terminates():
    # The object starts 4 m ahead, 1 m to the right, crossing: after one step 2.06 m apart.
    env = make(object_start=(-6.0, 9.0, math.pi / 2))
    env.reset(seed=0)
    _, _, terminated, truncated, info = env.step(act(4.0))
    assert info["distance"] == pytest.approx(math.hypot(2.0, 0.5), abs=1e-3)
    assert info["collision"] and terminated and not truncated
    assert not info["is_success"]
    assert info["risk"] > 0.0


def test_no_collision_just_outside_the_discs():
    env = near_object_env()
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(act(4.0))
    assert info["distance"] > 3.0 and not info["collision"] and not terminated


def test_reaching_the_goal_terminates_with_success():
    s = Scenario.preset("low")
    kappa, v = s.path.curvature, s.ego.v_ref
    start = tuple(float(c) for c in point(s.path, -3.0))
    env = make(ego_start=start, object_start=(100.0, -100.0, 0.0))
    _, info = env.reset(seed=0)
    assert info["lambda"] == pytest.approx(-3.0) and not info["is_success"]
    _, reward, terminated, _, info = env.step(act(v, kappa * v))
    assert not terminated and info["lambda"] == pytest.approx(-1.0)
    assert reward == pytest.approx(0.0, abs=1e-9)  # on the path at v_ref
    _, _, terminated, truncated, info = env.step(act(v, kappa * v))
    assert info["lambda"] == pytest.approx(1.0)
    assert terminated and not truncated and info["is_success"] and not info["collision"]


def test_truncation_at_max_steps(short_scenario):
    env = make(scenario=short_scenario)
    env.reset(seed=0)
    for k in range(1, short_scenario.max_steps + 1):
        _, _, terminated, truncated, info = env.step(act(0.0))
        assert not terminated
        assert truncated == (k == short_scenario.max_steps)
    assert env.steps == short_scenario.max_steps
    env.reset()
    assert env.steps == 0


def test_episode_risk_sums_the_risk_since_reset():
    """Safety-Gymnasium's per-episode cost: the running sum of ``info["risk"]``, zeroed by reset."""
    env = near_object_env(uncertainty="high", object_motion="sampled", max_steps=6)
    rng = np.random.default_rng(3)
    for seed in (0, 1):
        _, info = env.reset(seed=seed)
        assert info["episode_risk"] == 0.0
        total, done = 0.0, False
        while not done:
            _, _, terminated, truncated, info = env.step(act(rng.uniform(3.0, 5.0), 0.0))
            total += info["risk"]
            assert info["episode_risk"] == total
            done = terminated or truncated
        assert total > 0.0  # the episodes pass the object


# ---------------------------------------------------------------- several objects
@pytest.mark.parametrize(
    "kwargs",
    [
        {"scene": "two_crossing"},
        {
            "scene": "two_crossing",
            "object_slots": 3,
            "object_motion": "sampled",
            "risk_estimator": "monte_carlo",
        },
        {"scene": "four_crossing", "randomize": True, "variations": risk_env.Variations(object_count=True)},
    ],
)
def test_check_env_with_several_objects(kwargs):
    checked(gym.make(ENV_ID, render_mode="rgb_array", renderer="basic", **kwargs).unwrapped)


def test_sb3_checker_passes_with_several_objects():
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    for kwargs in ({}, {"scene": "two_crossing", "object_slots": 3}):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # its advice on unnormalised Box spaces
            env_checker.check_env(gym.make(ENV_ID, **kwargs), warn=True)


def test_scene_and_slots_arguments():
    env = make(scene="two_crossing", uncertainty="high")
    assert env.scenario == Scenario.preset("high", scene="two_crossing") and env.object_slots == 2
    assert env.observation_space.shape == (observation.size(2),) and len(env.estimators) == 2
    obs, info = env.reset(seed=0)
    assert info["objects"].shape == (2, 4) and info["risk_terms"].shape == (2,)
    np.testing.assert_array_equal(info["object"], info["objects"][0])
    assert env.observation_slices["object_1"] == observation.slot(1)
    with pytest.raises(ValueError, match=r"2 objects but object_slots = 1: objects\[1\] would have no"):
        make(scene="two_crossing", object_slots=1)
    with pytest.raises(ValueError, match="object_slots must be an integer >= 1"):
        make(object_slots=0)
    with pytest.raises(TypeError, match="object_slots must be an integer"):
        make(object_slots=2.0)
    with pytest.raises(ValueError, match="unknown scene 'three'"):
        make(scene="three")
    with pytest.raises(TypeError, match="not both.*'scene'"):
        make(scenario=Scenario(), scene="two_crossing")
    with pytest.raises(ValueError, match=r"objects\[1\]\.radius must be > 0"):
        make(objects=[{}, {"radius": -1.0}])


def test_randomized_object_counts_flag_absent_slots():
    env = make(scene="four_crossing", randomize=True, variations=risk_env.Variations(object_count=True))
    counts = set()
    for seed in range(40):
        obs, info = env.reset(seed=seed)
        m = len(env.scenario.objects)
        counts.add(m)
        parts = observation.split(obs, slots=4)
        assert parts.present.tolist() == [i < m for i in range(4)] == info["present"].tolist()
        assert np.all(info["objects"][m:] == 0.0) and info["risk_terms"].shape == (4,)
        obs, _, _, _, info = env.step(act(4.0))
        assert np.all(info["risk_terms"][m:] == 0.0)
        assert env.object_measurements.shape == (m, 5)
    assert counts == {1, 2, 3, 4}
    # without object_count the draws are those of a single-object scenario's, object by object
    one, two = make(randomize=True), make(randomize=True, scene="two_crossing")
    one.reset(seed=3)
    two.reset(seed=3)
    assert one.scenario.path == two.scenario.path and one.scenario.object == two.scenario.object


def test_single_object_episodes_are_what_they_were():
    """A seeded single-object episode in numbers recorded before the object slots (sampled
    motion, randomised start, Monte Carlo risk: every draw in its old order)."""
    env = make(
        randomize=True,
        object_motion="sampled",
        risk_estimator="monte_carlo",
        mc_samples=64,
        uncertainty="high",
        object_start=(0.0, 2.0, 1.57),
    )
    env.reset(seed=7)
    for _ in range(6):
        _, _, _, _, info = env.step(act(3.0, 0.1))
    recorded = [-1.8997528111506896, 10.166160269994217, 1.2734591827393456, 2.404035460734087]
    assert info["object"].tolist() == recorded
    assert info["episode_risk"] == 4277.514743041258
