"""The PPO baseline: its fixed maps, the SB3 view of the batched env, training in a subprocess,
loading, and the shipped policy on the paper's scenario."""

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
from agents.ppo import FEATURES, InputLimits, PPOAgent, features, to_inputs  # noqa: E402
from agents.ppo_env import PolicyView, SB3VecEnv  # noqa: E402
from benchmarks.rollout import rollout  # noqa: E402
from risk_env import Scenario, observation  # noqa: E402

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
    """:func:`agents.ppo.features` as it was before the object slots, on the old 15-entry layout
    (ego pose 0..2, input 3..4, object 5..9, lambda 10, path error 11..14): the shipped policies
    were trained on exactly these numbers."""
    o = np.atleast_2d(np.asarray(obs, dtype=float))
    x, y, theta = (o[:, i] for i in range(3))
    v, omega = o[:, 3], o[:, 4]
    ox, oy, otheta, ov = (o[:, i] for i in (5, 6, 7, 8))
    c, s = np.cos(theta), np.sin(theta)
    dx, dy = ox - x, oy - y
    rel_heading = otheta - theta
    vx = ov * np.cos(rel_heading) - v
    vy = ov * np.sin(rel_heading)
    raw = np.stack(
        (*(o[:, 11:15].T), v, omega, c * dx + s * dy, -s * dx + c * dy, np.cos(rel_heading))
        + (np.sin(rel_heading), vx, vy, np.hypot(dx, dy), o[:, 10]),
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
    """On single-object scenes the features are bit for bit those of the old layout, so the
    shipped policies act exactly as they were trained to."""
    obs = _episode_observations()
    assert obs.shape[1] == observation.SIZE and len(obs) > 200
    old = obs[:, _OLD_ORDER]
    assert features(obs).tobytes() == _features_before(old).tobytes()
    for row, before in zip(obs[:20], old[:20], strict=True):
        assert features(row).tobytes() == _features_before(before)[0].tobytes()
    agent = PPOAgent.load(SHIPPED / f"{name}.zip")
    action, _ = agent.model.predict(_features_before(old), deterministic=True)
    expected = to_inputs(action, old[:, 3:5], agent.limits)
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
    venv.set_attr("reward_risk_weight", 3.0)
    assert venv.get_attr("reward_risk_weight") == [3.0] * 4
    with pytest.raises(ValueError, match="same-step"):
        SB3VecEnv(gym.make_vec(risk_env.ENV_ID, num_envs=2))


def _train(tmp_path: Path, *flags: str) -> dict:
    out = tmp_path / "ppo"
    command = [sys.executable, "-m", "benchmarks.train_ppo", "--out", str(out), "--total-timesteps", "1024"]
    command += ["--num-envs", "8", "--n-steps", "64", "--batch-size", "256", "--no-progress-bar", *flags]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "env steps/s including updates" in done.stdout
    return json.loads((out / "model.json").read_text())


def test_train_save_load_predict_in_a_subprocess(tmp_path: Path) -> None:
    meta = _train(tmp_path, "--checkpoint-every", "512")
    assert meta["timesteps"] >= 1024 and meta["steps_per_s"] > 0
    assert list((tmp_path / "ppo" / "model_checkpoints").glob("model_*_steps.zip"))
    agent = PPOAgent.load(tmp_path / "ppo" / "model.zip")
    assert agent.metadata["args"]["num_envs"] == 8
    obs, _ = gym.make(risk_env.ENV_ID).reset(seed=0)
    action, state = agent.predict(obs)
    assert action.shape == (2,) and state is None and np.all(np.isfinite(action))
    assert agent.predict(np.stack([obs] * 3))[0].shape == (3, 2)
    with pytest.raises(ValueError, match="non-finite"):
        agent.predict(np.full(observation.SIZE, np.nan))


def test_lagrangian_moves_beta_toward_the_cost_limit(tmp_path: Path) -> None:
    up = _train(tmp_path / "up", "--lagrangian", "--cost-limit", "-1", "--dual-lr", "1", "--risk-weight", "2")
    assert up["final_rollout"]["beta"] > 2.0  # cost above the limit: the penalty grows
    down = _train(tmp_path / "down", "--lagrangian", "--cost-limit", "1e9", "--risk-weight", "2")
    assert down["final_rollout"]["beta"] == 0.0  # far below the limit: the penalty vanishes


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
