"""The vectorised env as a PPO policy trains on it.

- :class:`PolicyView`: a Gymnasium vector wrapper that shows the policy :func:`agents.ppo.policy.features`
  and applies its [-1, 1] actions through :func:`agents.ppo.policy.to_inputs`, exactly as
  :class:`agents.ppo.policy.PPOAgent` does when it drives;
- :class:`SB3VecEnv`: a Gymnasium vector env with same-step autoreset seen as a
  stable-baselines3 ``VecEnv`` (per-copy info dicts with ``terminal_observation``,
  ``TimeLimit.truncated``, and the episode's ``episode_cost``, ``collision`` and ``is_success``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from stable_baselines3.common.vec_env import VecEnv

from agents.ppo.policy import EPSILON_UNIT, FEATURES, Context, FeatureSpec, InputLimits, features, to_inputs
from risk_env import checks
from risk_env import observation as layout
from risk_env.envs.vector_infos import masked
from risk_env.scenario.parts import Uncertainty


@dataclass(frozen=True)
class RewardWeights:
    """The PPO reward's weights; per step (episode end: the goal bonus once)::

        r = -path_error ||e_{k+1}|| + progress (lambda_{k+1} - lambda_k) + goal [goal reached]
            - beta c_k,   c_k = max(0, R_{k+1|k} - epsilon) / cost_scale + collision [collided]

    The env's own reward (the paper's ``-||e|| - w R``) is not used: the view replaces it.
    """

    path_error: float = 1.0
    """Weight of the path error term [reward per unit of ||e||]."""
    progress: float = 1.0
    """Weight of the progress along the path [reward per m of lambda]."""
    goal: float = 10.0
    """Bonus on the step that reaches the goal [reward]."""
    cost_scale: float = 1000.0
    """Risk above epsilon per unit of cost [the severity's unit, J by default]."""
    collision: float = 1.0
    """Cost of a collision step [cost units]."""


TERMS = ("path_error", "progress", "goal", "cost")
"""Names of the PPO reward's terms in ``info["rewards"]`` (the cost term is ``-beta c_k``)."""


class PolicyView(VectorWrapper):
    """Features in, [-1, 1] actions out, the PPO reward, for a vectorised ``RiskCrossing-v0``.

    With a :class:`~agents.ppo.policy.FeatureSpec` the policy also sees each copy's :class:`Context`:
    epsilon drawn per episode from ``tolerances`` (``rng``), the uncertainty fixed per copy
    (``uncertainties``, one per copy: :class:`LevelMix` gives them). ``info["rewards"]`` holds
    the terms of :class:`RewardWeights` ``(B,)`` each, ``info["cost"]`` the cost ``c_k`` (both in
    ``final_info`` too for an ended copy). ``risk_weight`` is beta (the trainer sets it).
    """

    def __init__(
        self,
        env: VectorEnv,
        limits: InputLimits,
        spec: FeatureSpec | None = None,
        weights: RewardWeights | None = None,
        tolerances: Sequence[float] = (0.0,),
        uncertainties: Sequence[Uncertainty] | None = None,
        risk_weight: float = 0.0,
        seed: int = 0,
    ) -> None:
        super().__init__(env)
        self.limits = limits
        self.features = spec
        self.weights = weights or RewardWeights()
        self.tolerances = np.asarray(tolerances, dtype=float)
        self.risk_weight = float(risk_weight)
        """beta: reward per unit of cost."""
        n = env.num_envs
        if uncertainties is None:
            uncertainties = (
                getattr(env.unwrapped, "uncertainties", None) or [env.unwrapped.base_scenario.uncertainty] * n
            )
        self.uncertainties = list(uncertainties)
        self.rng = np.random.default_rng(seed)
        self.epsilon = np.zeros(n)
        """Each copy's epsilon in its current episode."""
        self._context = np.array([Context(0.0, u).array() for u in self.uncertainties])
        size = FEATURES if spec is None else spec.size
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (size,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, n)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, n)
        self._last_input = np.zeros((n, 2))
        self._lambda = np.zeros(n)

    def _draw(self, mask: np.ndarray) -> None:
        """New epsilons for the copies in ``mask`` (a new episode each)."""
        k = int(mask.sum())
        if k:
            self.epsilon[mask] = self.tolerances[self.rng.integers(len(self.tolerances), size=k)]
            self._context[mask, 0] = np.log1p(self.epsilon[mask] / EPSILON_UNIT) / np.log1p(5.0)

    def _features(self, obs: np.ndarray, context: np.ndarray) -> np.ndarray:
        return features(obs) if self.features is None else self.features(obs, context)

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._last_input = obs[:, layout.EGO_INPUT].astype(float)
        self._lambda = np.asarray(info["lambda"], dtype=float).copy()
        self._draw(np.ones(self.num_envs, dtype=bool))
        return self._features(obs, self._context), info

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        inputs = to_inputs(actions, self._last_input, self.limits)
        obs, _, terminated, truncated, info = self.env.step(inputs)
        self._last_input = obs[:, layout.EGO_INPUT].astype(float)
        done = terminated | truncated
        final = info.get("final_info", info)
        last = {k: np.where(done, final[k], info[k]) for k in ("lambda", "risk", "collision", "is_success")}
        error = -np.where(done, final["rewards"]["path_error"], info["rewards"]["path_error"])
        w = self.weights
        cost = np.maximum(last["risk"] - self.epsilon, 0.0) / w.cost_scale + w.collision * last["collision"]
        terms = {
            "path_error": -w.path_error * error,
            "progress": w.progress * (last["lambda"] - self._lambda),
            "goal": w.goal * last["is_success"],
            "cost": -self.risk_weight * cost,
        }
        reward = sum(terms.values())
        self._lambda = np.asarray(info["lambda"], dtype=float).copy()  # an ended copy's: its reset's
        info["rewards"], info["cost"] = terms, cost
        if done.any():
            context = self._context.copy()  # the ended episodes' context, for their last features
            final = dict(final, rewards=terms, cost=cost)
            info["final_info"] = final
            seen = np.full(self.num_envs, None, dtype=object)  # filled one by one: never a 2-D array
            for i, o in enumerate(info["final_obs"]):
                if o is not None:
                    seen[i] = self._features(o, context[i])
            info["final_obs"] = seen
            self._draw(done)
        return self._features(obs, self._context), reward, terminated, truncated, info


class LevelMix(VectorEnv):
    """Batched ``RiskCrossing-v0`` copies split over uncertainty levels: one batched env per level
    (``np.array_split`` of ``num_envs``), stepped in turn and seen as one ``VectorEnv``.

    ``uncertainties``: each copy's :class:`~risk_env.scenario.parts.Uncertainty` ``(num_envs,)``.
    Takes the batched env's keyword arguments (same-step autoreset).
    """

    def __init__(self, num_envs: int, levels: Sequence[str], **kwargs: Any) -> None:
        import risk_env

        sizes = [len(a) for a in np.array_split(np.arange(num_envs), len(levels))]
        self.envs = [
            gym.make_vec(
                risk_env.ENV_ID,
                num_envs=k,
                vectorization_mode="vector_entry_point",
                autoreset_mode="same_step",
                uncertainty=level,
                **kwargs,
            ).unwrapped
            for level, k in zip(levels, sizes, strict=True)
            if k > 0
        ]
        self.sizes = [e.num_envs for e in self.envs]
        self.num_envs = num_envs
        first = self.envs[0]
        self.base_scenario = first.base_scenario
        self.uncertainties = [e.base_scenario.uncertainty for e in self.envs for _ in range(e.num_envs)]
        self.metadata = dict(first.metadata)
        self.render_mode = None
        self.single_observation_space = first.single_observation_space
        self.single_action_space = first.single_action_space
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        self._bounds = np.cumsum([0, *self.sizes])

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every copy; ``seed`` an int (copy i gets seed + i) or one per copy."""
        if seed is not None:  # an integer of any integral type, or one per copy
            seed = checks.seeds(seed, self.num_envs)
        outs = [
            e.reset(seed=None if seed is None else list(seed[a:b]), options=options)
            for e, a, b in zip(self.envs, self._bounds[:-1], self._bounds[1:], strict=True)
        ]
        return np.concatenate([o for o, _ in outs]), merge([i for _, i in outs], self.sizes)

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        outs = [
            e.step(actions[a:b])
            for e, a, b in zip(self.envs, self._bounds[:-1], self._bounds[1:], strict=True)
        ]
        obs, reward, terminated, truncated = (np.concatenate([o[j] for o in outs]) for j in range(4))
        return obs, reward, terminated, truncated, merge([o[4] for o in outs], self.sizes)

    def close_extras(self, **kwargs: Any) -> None:
        for e in self.envs:
            e.close()


def merge(infos: list[dict[str, Any]], sizes: list[int]) -> dict[str, Any]:
    """Vector infos of consecutive batches concatenated per key (recursing into dicts); a key some
    batch lacks (``final_info``, ``final_obs`` and their masks) is filled as "not set" there."""
    out: dict[str, Any] = {}
    for key in dict.fromkeys(k for info in infos for k in info):
        parts = []
        for info, n in zip(infos, sizes, strict=True):
            if key in info:
                parts.append(info[key])
            elif key.startswith("_"):
                parts.append(np.zeros(n, dtype=bool))
            elif key == "final_obs":
                parts.append(np.full(n, None, dtype=object))
            else:
                parts.append(masked(info, np.zeros(n, dtype=bool)))
        if isinstance(parts[0], dict):
            out[key] = merge(parts, sizes)
        else:
            out[key] = np.concatenate(parts)
    return out


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
        terms = info.get("rewards", {})
        infos: list[dict[str, Any]] = []
        for i in range(self.num_envs):
            item: dict[str, Any] = {"cost": cost[i], "rewards": {k: v[i] for k, v in terms.items()}}
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

    def _target(self, attr_name: str) -> Any:
        """The outermost wrapper (or the env) that has ``attr_name``."""
        env = self.env
        while isinstance(env, VectorWrapper) and not hasattr(env, attr_name):
            env = env.env
        return env

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self._target(attr_name), attr_name)] * len(list(self._get_indices(indices)))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Sets the attribute on the batched env, that is for every copy (``indices`` must be all)."""
        if len(list(self._get_indices(indices))) != self.num_envs:
            raise ValueError("the batched env shares its attributes: set them for every copy")
        setattr(self._target(attr_name), attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list:
        raise NotImplementedError("the batched env has no per-copy env objects to call methods on")

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: Any = None) -> Sequence[bool]:
        return [False] * len(list(self._get_indices(indices)))
