"""The PPO baseline: its fixed maps, the SB3 view of the batched env, training (in this process;
in a subprocess in the slow tests), loading, and the shipped policy on the paper's scenario."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import risk_env  # noqa: E402
from agents.ppo.policy import FEATURES, Context, FeatureSpec, InputLimits, PPOAgent, features, to_inputs  # noqa: E402
from agents.ppo.training import TERMS, LevelMix, PolicyView, RewardWeights, SB3VecEnv  # noqa: E402
from benchmarks.ppo_eval import best_seed, seed_table  # noqa: E402
from benchmarks.rollout import rollout  # noqa: E402
from risk_env import Scenario, observation  # noqa: E402
from risk_env.scenario.parts import Uncertainty  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "agents" / "models"


def test_features_are_in_the_egos_frame() -> None:
    obs = np.zeros(observation.SIZE)
    obs[observation.EGO_POSE] = (10.0, 5.0, math.pi / 2)  # ego at (10, 5) heading north
    obs[3] = 2.0
    obs[observation.PRESENT] = 1.0
    obs[observation.OBJECT][:4] = (10.0, 25.0, math.pi, 3.0)  # object 20 m ahead, heading west at 3 m/s
    f = features(obs) * np.array([5, 5, 1, 4, 4, 0.8, 20, 20, 1, 1, 8, 8, 20, 100])
    assert f.shape == (FEATURES,)
    np.testing.assert_allclose(f[6:8], (20.0, 0.0), atol=1e-5)  # ahead, not beside
    np.testing.assert_allclose(f[8:10], (0.0, 1.0), atol=1e-6)  # heading to the ego's left
    np.testing.assert_allclose(f[10:12], (-2.0, 3.0), atol=1e-5)  # relative velocity, ego frame
    np.testing.assert_allclose(f[12], 20.0, atol=1e-5)
    np.testing.assert_allclose(features(np.stack([obs, obs]))[1], features(obs))


def _features_before(obs: np.ndarray) -> np.ndarray:
    """:func:`agents.ppo.policy.features` as it was before the object slots, on the old 15-entry layout
    (ego pose 0..2, input 3..4, object 5..9, lambda 10, path error 11..14): the shipped policies
    were trained on these numbers (here sin, cos and hypot entry by entry from ``math``, as the
    features now take them to be the same on every CPU)."""
    cos, sin, hypot = (np.vectorize(f, otypes=[float]) for f in (math.cos, math.sin, math.hypot))
    o = np.atleast_2d(np.asarray(obs, dtype=float))
    x, y, theta = (o[:, i] for i in range(3))
    v, omega = o[:, 3], o[:, 4]
    ox, oy, otheta, ov = (o[:, i] for i in (5, 6, 7, 8))
    c, s = cos(theta), sin(theta)
    dx, dy = ox - x, oy - y
    rel_heading = otheta - theta
    vx = ov * cos(rel_heading) - v
    vy = ov * sin(rel_heading)
    raw = np.stack(
        (*(o[:, 11:15].T), v, omega, c * dx + s * dy, -s * dx + c * dy, cos(rel_heading))
        + (sin(rel_heading), vx, vy, hypot(dx, dy), o[:, 10]),
        axis=-1,
    )
    scale = np.array([5.0, 5.0, 1.0, 4.0, 4.0, 0.8, 20.0, 20.0, 1.0, 1.0, 8.0, 8.0, 20.0, 100.0])
    return (raw / scale).astype(np.float32)


_OLD_ORDER = [0, 1, 2, 3, 4, 11, 12, 13, 14, 15, 5, 6, 7, 8, 9]
"""The entries of a one-slot observation in the order of the old 15-entry layout."""


def _episode_observations() -> np.ndarray:
    """Observations of single-object episodes: the three levels, sampled motion, randomised."""
    out = []
    for kwargs in ({}, {"uncertainty": "high", "object_motion": "sampled"}, {"randomize": True}):
        env = gym.make(risk_env.ENV_ID, **kwargs)
        rng = np.random.default_rng(0)
        for seed in range(3):
            obs, _ = env.reset(seed=seed)
            out.append(obs)
            for _ in range(40):
                obs, _, terminated, truncated, _ = env.step(rng.uniform([-1.0, -0.8], [8.0, 0.8]))
                out.append(obs)
                if terminated or truncated:
                    break
    return np.array(out)


@pytest.mark.parametrize("name", ["ppo_penalty", "ppo_lagrangian"])
def test_shipped_policies_see_what_they_saw_before_the_object_slots(name: str) -> None:
    """On single-object scenes the 14 base features are bit for bit those of the old layout, and
    the shipped policies see them followed by their context."""
    obs = _episode_observations()
    assert obs.shape[1] == observation.SIZE and len(obs) > 200
    old = obs[:, _OLD_ORDER]
    assert features(obs).tobytes() == _features_before(old).tobytes()
    for row, before in zip(obs[:20], old[:20], strict=True):
        assert features(row).tobytes() == _features_before(before)[0].tobytes()
    agent = PPOAgent.load(SHIPPED / f"{name}.zip")
    assert agent.spec is not None and agent.context is not None  # conditioned on epsilon and the level
    seen = np.concatenate(
        [_features_before(old), agent.spec(obs, agent.context.array())[:, FEATURES:]], axis=1
    )
    expected = to_inputs(np.clip(agent.policy(seen), -1.0, 1.0), old[:, 3:5], agent.limits)
    np.testing.assert_array_equal(agent.predict(obs)[0], expected)
    # a second slot (absent, or a second object) changes nothing: the policy reads the first object
    two = np.concatenate([obs, np.zeros((len(obs), observation.SLOT_SIZE), dtype=np.float32)], axis=1)
    np.testing.assert_array_equal(agent.predict(two)[0], expected)
    with pytest.raises(ValueError, match="hold no object"):
        features(np.zeros(observation.size(2)))


def test_actions_respect_rate_and_input_limits() -> None:
    limits = InputLimits.of(Scenario.preset())
    assert (limits.dv_max, limits.domega_max) == (1.5, 0.8)
    last = np.array([[0.0, 0.0], [7.5, 0.7], [-3.9, -0.5]])
    out = to_inputs(np.array([[1.0, -1.0], [1.0, 1.0], [-5.0, 0.5]]), last, limits)
    np.testing.assert_allclose(out, [[1.5, -0.8], [8.0, 0.8], [-4.0, -0.1]])


def test_sb3_view_reports_episode_cost_and_terminal_observation() -> None:
    env = gym.make_vec(risk_env.ENV_ID, num_envs=4, autoreset_mode="same_step", max_steps=12, randomize=True)
    venv = SB3VecEnv(PolicyView(env, InputLimits.of(env.unwrapped.base_scenario)))
    venv.seed(3)
    obs = venv.reset()
    assert obs.shape == (4, FEATURES)
    rng = np.random.default_rng(0)
    running = np.zeros(4)
    finished = 0
    for _ in range(30):
        obs, reward, done, infos = venv.step(rng.uniform(-1, 1, (4, 2)).astype(np.float32))
        running += [info["cost"] for info in infos]
        for i in np.flatnonzero(done):
            assert infos[i]["terminal_observation"].shape == (FEATURES,)
            assert infos[i]["episode_cost"] == pytest.approx(running[i])
            assert infos[i]["TimeLimit.truncated"] == (
                not infos[i]["collision"] and not infos[i]["is_success"]
            )
            running[i] = 0.0
            finished += 1
    assert finished >= 4
    venv.set_attr("risk_weight", 3.0)
    assert venv.get_attr("risk_weight") == [3.0] * 4
    with pytest.raises(ValueError, match="same-step"):
        SB3VecEnv(gym.make_vec(risk_env.ENV_ID, num_envs=2))


SMALL_RUN = ("--num-envs", "4", "--n-steps", "32", "--batch-size", "64", "--no-progress-bar")
"""Rollouts of 4 copies x 32 steps = 128 env steps, one update (two minibatches) after each."""


def _train(tmp_path: Path, *flags: str, steps: int = 1024) -> dict:
    """Train with ``python -m benchmarks.train_ppo`` in a subprocess for ``steps`` env steps (8
    copies, rollouts of 64 steps each)."""
    out = tmp_path / "ppo"
    command = [
        sys.executable,
        "-m",
        "benchmarks.train_ppo",
        "--out",
        str(out),
        "--total-timesteps",
        str(steps),
    ]
    command += ["--num-envs", "8", "--n-steps", "64", "--batch-size", "256", "--no-progress-bar", *flags]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "env steps/s including updates" in done.stdout
    return json.loads((out / "model.json").read_text())


@pytest.fixture
def keep_torch_threads():
    """Training sets torch's thread count (benchmarks.train_ppo): the test process gets its own back."""
    import torch

    threads = torch.get_num_threads()
    yield
    torch.set_num_threads(threads)


def test_train_save_load_predict(tmp_path: Path, capsys, keep_torch_threads) -> None:
    """One short training (the prediction features, the Lagrangian) through the command's ``main``
    in this process (torch already loaded; the ``slow`` tests below train with ``python -m`` in a
    subprocess): saved, loaded, acting; told epsilon and the level of the scenario it is loaded
    for, in the severity it was trained with. The cost is above the limit, so beta grows by dual
    ascent (two rollouts, one update each)."""
    from benchmarks import train_ppo

    lagrangian = ("--lagrangian", "--cost-limit", "-1", "--dual-lr", "1", "--risk-weight", "2")
    argv = ["--out", str(tmp_path / "ppo"), "--total-timesteps", "256", *SMALL_RUN]
    train_ppo.main([*argv, "--checkpoint-every", "128", "--prediction", *lagrangian])
    assert "env steps/s including updates" in capsys.readouterr().out
    meta = json.loads((tmp_path / "ppo" / "model.json").read_text())
    assert meta["timesteps"] >= 256 and meta["steps_per_s"] > 0
    assert meta["final_rollout"]["beta"] > 2.0 + 1.0  # each update adds dual_lr (cost - limit) >= 1
    assert meta["features"] == FeatureSpec(prediction=True).size
    assert len(list((tmp_path / "ppo" / "model_checkpoints").glob("model_*_steps.zip"))) == 2
    agent = PPOAgent.load(tmp_path / "ppo" / "model.zip")
    assert agent.metadata["args"]["num_envs"] == 4
    obs, _ = gym.make(risk_env.ENV_ID).reset(seed=0)
    action, state = agent.predict(obs)
    assert action.shape == (2,) and state is None and np.all(np.isfinite(action))
    assert agent.predict(np.stack([obs] * 3))[0].shape == (3, 2)
    with pytest.raises(ValueError, match="non-finite"):
        agent.predict(np.full(observation.SIZE, np.nan))
    env = gym.make(risk_env.ENV_ID, uncertainty="high", risk_tolerance=1500.0)
    agent = PPOAgent.load(tmp_path / "ppo" / "model.zip", scenario=env.unwrapped.scenario)
    assert agent.context == Context(1500.0, env.unwrapped.scenario.uncertainty)
    assert agent.predict(env.reset(seed=0)[0])[0].shape == (2,)
    other = gym.make(risk_env.ENV_ID, severity="probability", risk_tolerance=0.1)
    with pytest.raises(ValueError, match="severity"):
        PPOAgent.load(tmp_path / "ppo" / "model.zip", scenario=other.unwrapped.scenario)


@pytest.mark.slow  # test_train_save_load_predict trains with these flags (in this process)
def test_lagrangian_raises_beta_above_the_cost_limit(tmp_path: Path) -> None:
    """One rollout (beta moves after every rollout): the cost is above the limit, the penalty grows."""
    flags = ("--lagrangian", "--cost-limit", "-1", "--dual-lr", "1", "--risk-weight", "2")
    assert _train(tmp_path, *flags, steps=512)["final_rollout"]["beta"] > 2.0


@pytest.mark.slow
def test_lagrangian_drops_beta_to_zero_far_below_the_cost_limit(tmp_path: Path) -> None:
    flags = ("--lagrangian", "--cost-limit", "1e9", "--risk-weight", "2")
    assert _train(tmp_path, *flags, steps=512)["final_rollout"]["beta"] == 0.0  # clipped at 0


def test_load_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="train_ppo"):
        PPOAgent.load(tmp_path / "missing.zip")


@pytest.mark.parametrize("name", ["ppo_penalty", "ppo_lagrangian"])
@pytest.mark.parametrize("uncertainty", ["low", "medium", "high"])
def test_shipped_policy_reaches_the_goal_without_collision(name: str, uncertainty: str) -> None:
    agent = PPOAgent.load(SHIPPED / f"{name}.zip")
    record = rollout(agent, gym.make(risk_env.ENV_ID, uncertainty=uncertainty), seed=0)
    assert record.success and not record.collision
    assert np.all(np.abs(np.diff(record.actions[:, 0])) <= agent.limits.dv_max + 1e-5)  # obs holds float32


def test_prediction_features_in_the_egos_frame() -> None:
    """An object 20 m ahead driving toward the ego at 2 m/s: its predicted mean comes closer by
    1 m per step (dt 0.5 s), its box grows by Delta per step on each axis."""
    obs = np.zeros(observation.SIZE)
    obs[observation.EGO_POSE] = (0.0, 0.0, math.pi / 2)  # heading north
    obs[observation.PRESENT] = 1.0
    obs[observation.OBJECT] = (0.0, 20.0, -math.pi / 2, 2.0, 0.0)
    spec = FeatureSpec(prediction=True, dt=0.5, steps=(2, 4))
    ctx = Context(2500.0, Scenario.preset("high").uncertainty).array()
    f = spec(obs, ctx)
    assert f.shape == (spec.size,) == (FEATURES + 3 + 8,)
    np.testing.assert_allclose(f[FEATURES : FEATURES + 3], (1.0, 1.5 / 1.5, 3.0 / 3.0), atol=1e-6)
    pred = f[FEATURES + 3 :].reshape(2, 4) * np.array([20.0, 20.0, 10.0, 10.0])
    np.testing.assert_allclose(pred, [[18.0, 0.0, 6.0, 6.0], [16.0, 0.0, 12.0, 12.0]], atol=1e-4)
    zero = Context(0.0, Scenario.preset("low").uncertainty).array()
    assert zero[0] == 0.0 and spec(np.stack([obs, obs]), zero).shape == (2, spec.size)


def test_policy_view_reward_terms_and_epsilon_per_episode() -> None:
    """The reward is the sum of the named terms; progress is the change of lambda; each copy's
    epsilon comes from the tolerances and is redrawn when its episode ends; the levels split."""
    env = LevelMix(6, ["low", "high"], max_steps=12, randomize=True)
    assert env.sizes == [3, 3] and [u.box_growth[0] for u in env.uncertainties] == [1.0] * 3 + [3.0] * 3
    spec = FeatureSpec(prediction=True, dt=env.base_scenario.dt)
    weights = RewardWeights(path_error=1.0, progress=2.0, goal=5.0, cost_scale=100.0, collision=1.0)
    view = PolicyView(env, InputLimits.of(env.base_scenario), spec, weights, (0.0, 2500.0), risk_weight=3.0)
    obs, info = view.reset(seed=1)
    assert obs.shape == (6, spec.size) and set(view.epsilon) <= {0.0, 2500.0}
    np.testing.assert_allclose(obs[:, FEATURES], np.where(view.epsilon > 0, 1.0, 0.0), atol=1e-6)
    lam = info["lambda"].copy()
    ended = 0
    for _ in range(30):
        eps = view.epsilon.copy()
        obs, reward, terminated, truncated, info = view.step(np.ones((6, 2), dtype=np.float32) * [1.0, 0.0])
        done = terminated | truncated
        final = info.get("final_info", info)
        terms = info["rewards"]
        assert set(terms) == set(TERMS)
        np.testing.assert_allclose(reward, sum(terms.values()))
        last_lam = np.where(done, final["lambda"], info["lambda"])
        np.testing.assert_allclose(terms["progress"], 2.0 * (last_lam - lam))
        cost = np.maximum(np.where(done, final["risk"], info["risk"]) - eps, 0.0) / 100.0
        cost += np.where(done, final["collision"], info["collision"])
        np.testing.assert_allclose(terms["cost"], -3.0 * cost)
        np.testing.assert_allclose(terms["goal"], 5.0 * np.where(done, final["is_success"], False))
        for i in np.flatnonzero(done):
            assert info["final_obs"][i].shape == (spec.size,)
            ended += 1
        lam = info["lambda"].copy()
    assert ended >= 6


def test_seed_table_and_best_seed() -> None:
    results = {
        0: {"e_acc": 80.0, "collision_rate": 0.01, "goal_rate": 0.9, "episode_cost": 0.01, "d_min": 9.0},
        1: {"e_acc": 70.0, "collision_rate": 0.0, "goal_rate": 0.9, "episode_cost": 0.5, "d_min": 8.0},
        2: {"e_acc": 90.0, "collision_rate": 0.0, "goal_rate": 0.95, "episode_cost": 0.0, "d_min": 9.5},
    }
    assert best_seed(results, cost_limit=0.02) == 2  # seed 1 breaks the cost limit
    assert best_seed(results, cost_limit=1.0) == 2  # fewest collisions, then the goal rate
    table = seed_table(results, 2, "header")
    assert "| 2 (shipped) | 90.0 | 0.0% | 95.0% |" in table
    assert "| mean ± std over 3 | 80.0 ± 10.0 | 0.3% ± 0.6% |" in table


@pytest.mark.slow  # two trainings and their scoring; test_seed_table_and_best_seed is the fast test
def test_seeds_train_score_and_ship_the_best(tmp_path: Path) -> None:
    out = tmp_path / "ppo"
    command = [sys.executable, "-m", "benchmarks.train_ppo", "--out", str(out), "--total-timesteps", "512"]
    command += ["--num-envs", "4", "--n-steps", "64", "--batch-size", "128", "--no-progress-bar"]
    command += ["--seeds", "2", "--eval-episodes", "6", "--checkpoint-every", "0"]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    summary = json.loads((out / "model_seeds.json").read_text())
    assert set(summary["results"]) == {"0", "1"} and summary["best"] in (0, 1)
    best = out / "model_seeds" / f"model_seed{summary['best']}.zip"
    assert (out / "model.zip").read_bytes() == best.read_bytes()
    table = (out / "model_seeds.md").read_text()
    assert "mean ± std over 2" in table and f"| {summary['best']} (shipped) |" in table


def _two_crossing_observations() -> np.ndarray:
    """Observations ``(N, 22)`` of a two_crossing episode (sampled motion, random inputs)."""
    env = gym.make(risk_env.ENV_ID, scene="two_crossing", object_motion="sampled")
    obs, _ = env.reset(seed=1)
    rows, rng = [obs], np.random.default_rng(0)
    for _ in range(30):
        obs, _, terminated, truncated, _ = env.step(rng.uniform([0.0, -0.8], [8.0, 0.8]))
        rows.append(obs)
        if terminated or truncated:
            break
    return np.array(rows)


def test_two_slot_features_see_every_object_and_zero_an_absent_slot() -> None:
    """K = 2: 7 ego + 8 per slot + 3 context + 12 prediction per slot = 50 features; slot i's
    object features are those :func:`features` gives for that object alone; an absent slot is all
    zeros, its flag included, and leaves the other slot's features as they were."""
    obs = _two_crossing_observations()
    spec = FeatureSpec(prediction=True, slots=2)
    ctx = Context(1000.0, Uncertainty.preset("medium")).array()
    seen = spec(obs, ctx)
    assert spec.size == 50 and seen.shape == (len(obs), 50) and np.isfinite(seen).all()
    for i in range(2):  # slot i alone, in a one-slot observation, through the one-object features
        alone = np.concatenate([obs[:, :10], obs[:, observation.slot(i)]], axis=1)
        np.testing.assert_array_equal(seen[:, 7 + 8 * i], 1.0)
        np.testing.assert_allclose(seen[:, 8 + 8 * i : 15 + 8 * i], features(alone)[:, 6:13], atol=1e-6)
        one = FeatureSpec(prediction=True)(alone, ctx)[:, FEATURES + 3 :]
        np.testing.assert_allclose(seen[:, 26 + 12 * i : 38 + 12 * i], one, atol=1e-6)
    blank = obs.copy()
    blank[:, observation.slot(1)] = 0.0
    gone = spec(blank, ctx)
    assert not gone[:, 15:23].any() and not gone[:, 38:].any()
    np.testing.assert_array_equal(gone[:, :15], seen[:, :15])
    np.testing.assert_array_equal(gone[:, 23:38], seen[:, 23:38])
    with pytest.raises(ValueError, match="2 object slots"):
        spec(obs[:, : observation.SIZE], ctx)


def test_shipped_two_crossing_policy_drives_its_scene_only() -> None:
    """The two-object Lagrangian policy loads for two_crossing, acts finitely within the limits,
    and is listed for that scene only."""
    from benchmarks.rollout import AGENTS, available_agents, build_agent

    env = gym.make(risk_env.ENV_ID, scene="two_crossing", risk_tolerance=500.0)
    agent = build_agent(*AGENTS["ppo:lagrangian_two_crossing"], env)
    assert agent.spec is not None and agent.spec.slots == 2
    assert agent.metadata["args"]["scene"] == "two_crossing"
    obs = _two_crossing_observations()
    inputs, _ = agent.predict(obs)
    assert inputs.shape == (len(obs), 2) and np.isfinite(inputs).all()
    assert (inputs[:, 0] >= 0.0).all() and (inputs[:, 0] <= agent.limits.v_max).all()
    assert "ppo:lagrangian_two_crossing" in available_agents("two_crossing")
    assert "ppo:lagrangian_two_crossing" not in available_agents("paper")
    with pytest.raises(ValueError, match="2 object slots"):
        agent.predict(obs[0, : observation.SIZE])
