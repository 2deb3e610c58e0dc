"""The vectorised env as a PPO policy trains on it.

- :class:`PolicyView`: a Gymnasium vector wrapper that shows the policy :func:`agents.ppo.features`
  and applies its [-1, 1] actions through :func:`agents.ppo.to_inputs`, exactly as
  :class:`agents.ppo.PPOAgent` does when it drives;
- :class:`SB3VecEnv`: a Gymnasium vector env with same-step autoreset seen as a
  stable-baselines3 ``VecEnv`` (per-copy info dicts with ``terminal_observation``,
  ``TimeLimit.truncated``, and the episode's ``episode_cost``, ``collision`` and ``is_success``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from stable_baselines3.common.vec_env import VecEnv

from agents.ppo import FEATURES, InputLimits, features, to_inputs
from risk_env import observation as layout


class PolicyView(VectorWrapper):
    """Features in, [-1, 1] actions out, for a vectorised ``RiskCrossing-v0``."""

    def __init__(self, env: VectorEnv, limits: InputLimits) -> None:
        super().__init__(env)
        self.limits = limits
        n = env.num_envs
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (FEATURES,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, n)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, n)
        self._last_input = np.zeros((n, 2))

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._last_input = obs[:, layout.EGO_INPUT].astype(float)
        return features(obs), info

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        inputs = to_inputs(actions, self._last_input, self.limits)
        obs, reward, terminated, truncated, info = self.env.step(inputs)
        self._last_input = obs[:, layout.EGO_INPUT].astype(float)
        if "final_obs" in info:
            info["final_obs"] = np.array(
                [None if o is None else features(o) for o in info["final_obs"]], dtype=object
            )
        return features(obs), reward, terminated, truncated, info


class SB3VecEnv(VecEnv):
    """A Gymnasium ``VectorEnv`` (same-step autoreset) behind stable-baselines3's ``VecEnv`` API."""

    EPISODE_KEYS = ("episode_cost", "collision", "is_success")
    """Keys of the last step's info dict of each episode (pass them to ``VecMonitor``)."""

    def __init__(self, env: VectorEnv) -> None:
        if env.metadata.get("autoreset_mode") != AutoresetMode.SAME_STEP:
            raise ValueError(
                "stable-baselines3 needs same-step autoreset: build the env with autoreset_mode='same_step'"
            )
        self.env = env
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self._actions: np.ndarray | None = None
        self._episode_cost = np.zeros(env.num_envs)

    def reset(self) -> np.ndarray:
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        obs, _ = self.env.reset(seed=seeds)
        self._reset_seeds()
        self._episode_cost[:] = 0.0
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, reward, terminated, truncated, info = self.env.step(self._actions)
        done = terminated | truncated
        final = info.get("final_info", info)  # an ended copy's last step is in final_info
        cost = np.where(done, final["cost"], info["cost"])
        self._episode_cost += cost
        infos: list[dict[str, Any]] = []
        for i in range(self.num_envs):
            item: dict[str, Any] = {"cost": cost[i]}
            if done[i]:
                item.update(
                    terminal_observation=info["final_obs"][i],
                    episode_cost=float(self._episode_cost[i]),
                    collision=bool(final["collision"][i]),
                    is_success=bool(final["is_success"][i]),
                )
                item["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                self._episode_cost[i] = 0.0
            infos.append(item)
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        self.env.close()

    def _target(self) -> Any:
        return self.env.unwrapped

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self._target(), attr_name)] * len(list(self._get_indices(indices)))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Sets the attribute on the batched env, that is for every copy (``indices`` must be all)."""
        if len(list(self._get_indices(indices))) != self.num_envs:
            raise ValueError("the batched env shares its attributes: set them for every copy")
        setattr(self._target(), attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list:
        raise NotImplementedError("the batched env has no per-copy env objects to call methods on")

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: Any = None) -> Sequence[bool]:
        return [False] * len(list(self._get_indices(indices)))
