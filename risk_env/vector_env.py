"""``RiskCrossing-v0`` batched: B copies stepped at once with numpy, the risk of the whole batch in
one estimator call.

``gym.make_vec("RiskCrossing-v0", num_envs=64)`` builds it (the spec's ``vector_entry_point``);
``vectorization_mode="sync"`` or ``"async"`` builds Gymnasium's vector envs of single envs
instead. Copy i behaves exactly like ``gym.make("RiskCrossing-v0", ...)`` reset with
``seed + i``: the same arguments, its own generator drawn in the same order, the same transition
(:mod:`risk_env.transition`). Tests hold the three modes to the same numbers (to 1e-9: the
exact risk of one state and of a batch run through two numpy kernels that agree to ~1e-11).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from risk_env import checks, dynamics
from risk_env.checks import slack
from risk_env.env import RiskCrossingEnv
from risk_env.ops import NUMPY
from risk_env.path import PathBatch
from risk_env.prediction import Belief, predict
from risk_env.risk import MonteCarloRisk
from risk_env.scenario import Scenario
from risk_env.transition import move_object, observe, reward_terms
from risk_env.variations import vary


class RiskCrossingVectorEnv(VectorEnv):
    """B copies of :class:`~risk_env.env.RiskCrossingEnv` in numpy arrays.

    Takes the single env's keyword arguments (validated by building one) plus ``num_envs`` and
    ``autoreset_mode`` (Gymnasium's ``AutoresetMode``, next-step by default; ``"same_step"``
    suits stable-baselines3). Observations ``(B, 15)`` float32, actions ``(B, 2)`` in physical
    units, infos as Gymnasium's vector envs give them: every key of the single env's info as an
    array over copies, with its ``_key`` mask. Draws nothing (``render_mode`` must be None).
    """

    def __init__(
        self,
        num_envs: int = 1,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        num_envs = checks.integer("num_envs", num_envs, minimum=1)
        if render_mode is not None:
            raise ValueError(
                "the batched RiskCrossing-v0 does not render; use gym.make_vec(..., vectorization_mode="
                f"'sync') or gym.make for render_mode={render_mode!r}"
            )
        mode = _autoreset_mode(autoreset_mode)
        template = RiskCrossingEnv(**kwargs)  # the single env validates every argument
        self.template = template
        self.base_scenario: Scenario = template.base_scenario
        self.estimator = template.estimator
        self.object_motion = template.object_motion
        self.reward_risk_weight = template.reward_risk_weight
        self.randomize, self.variations = template.randomize, template.variations
        self.num_envs = num_envs
        self.render_mode = None
        self.metadata = {"autoreset_mode": mode, "render_modes": []}
        self.single_action_space = template.action_space
        self.single_observation_space = template.observation_space
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)

        n = num_envs
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._path = PathBatch.of(self.base_scenario.path, n)
        self._ego = np.zeros((3, n))  # c1, c2, theta (unwrapped)
        self._input = np.zeros((2, n))  # v, omega last applied
        self._object = np.zeros((5, n))  # c1, c2, theta, v, omega
        self._steps = np.zeros(n, dtype=np.int64)
        self._episode_risk = np.zeros(n)  # sum of the risk since each copy's reset
        self._autoreset = np.zeros(n, dtype=bool)
        self._started = False

    @property
    def epsilon(self) -> float:
        """The risk tolerance epsilon of every copy."""
        return self.base_scenario.risk_tolerance

    # ---------------------------------------------------------------- gym API
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the copies (``options={"reset_mask": (B,) bool}`` resets only those)."""
        n = self.num_envs
        options = dict(options or {})
        mask = np.asarray(options.pop("reset_mask", np.ones(n, dtype=bool)))
        if options:
            raise ValueError(
                f"RiskCrossing-v0 takes only the reset option 'reset_mask', got {sorted(options)}"
            )
        if mask.shape != (n,) or mask.dtype != bool:
            raise ValueError(
                f"reset_mask must be a bool array of shape ({n},), got {mask.dtype} {mask.shape}"
            )
        seeds = checks.seeds(seed, n)
        if not self._started and not mask.all():
            raise gym.error.ResetNeeded("the first reset must reset every copy")
        for i in np.flatnonzero(mask):
            if seeds[i] is not None or self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random(seeds[i])
        self._reset_copies(mask)
        self._started = True
        self._autoreset[mask] = False
        seen = self._observe()
        zero = np.zeros(n)
        return seen.obs, self._infos(seen, zero, stepped=np.zeros(n, dtype=bool))

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every copy with ``actions (B, 2)`` = (v [m/s], omega [rad/s]) per copy."""
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        n, s = self.num_envs, self.base_scenario
        mode = self.metadata["autoreset_mode"]
        if mode == AutoresetMode.NEXT_STEP and self._autoreset.any():
            self._reset_copies(self._autoreset)
        elif mode == AutoresetMode.DISABLED and self._autoreset.any():
            raise gym.error.ResetNeeded(
                f"copies {np.flatnonzero(self._autoreset).tolist()} have ended; reset them with"
                " options={'reset_mask': ...} (autoreset_mode is disabled)"
            )
        active = ~self._autoreset if mode == AutoresetMode.NEXT_STEP else np.ones(n, dtype=bool)
        v, omega = self._check_actions(actions, active)
        idx = np.flatnonzero(active)

        # 1. the ego moves
        x, y, theta = dynamics.unicycle_step(*(a[idx] for a in self._ego), v[idx], omega[idx], s.dt, NUMPY)
        self._ego[:, idx] = x, y, theta
        self._input[:, idx] = v[idx], omega[idx]
        # 2. the object moves; B = its one-step belief from the measurement before the move
        measurement = tuple(self._object[:, idx])
        belief = predict(s, measurement, steps=1)[1]
        uniforms = None
        if self.object_motion == "sampled":
            uniforms = np.array([self._rngs[i].random(3) for i in idx]).reshape(len(idx), 3)
        self._object[:, idx] = np.broadcast_arrays(*move_object(belief, measurement, uniforms))
        # 3. the risk R_{k+1|k} of the ego's new state against B
        risk = np.zeros(n)
        risk[idx] = self._risk(np.stack((x, y, theta, v[idx]), axis=-1), belief, idx)
        self._episode_risk[idx] += risk[idx]
        self._steps[idx] += 1
        # 4. reward terms, episode end, observation, info
        seen = self._observe()
        terminated = active & (seen.collision | seen.goal)
        truncated = active & (self._steps >= s.max_steps)
        infos = self._infos(seen, risk, stepped=active)
        rewards = infos["rewards"]["path_error"] + infos["rewards"]["risk"]  # 0 where not stepped
        done = terminated | truncated
        obs = seen.obs
        if mode == AutoresetMode.SAME_STEP and done.any():
            final_obs = np.full(n, None, dtype=object)
            for i in np.flatnonzero(done):
                final_obs[i] = obs[i]
            infos["final_info"] = _masked(infos, done)
            infos["_final_info"] = done.copy()
            infos["final_obs"], infos["_final_obs"] = final_obs, done.copy()
            self._reset_copies(done)
            reset_seen = self._observe()
            obs = reset_seen.obs
            fresh = self._infos(reset_seen, np.zeros(n), stepped=np.zeros(n, dtype=bool))
            infos.update({k: _where(done, fresh[k], infos[k]) for k in fresh if not k.startswith("_")})
        else:
            self._autoreset = done
        return obs, rewards, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        self.template.close()

    # ---------------------------------------------------------------- internals
    def _reset_copies(self, mask: np.ndarray) -> None:
        """Put the copies in ``mask`` at their episode's start (drawing it when randomising)."""
        for i in np.flatnonzero(mask):
            sc = (
                vary(self.base_scenario, self._rngs[i], self.variations)
                if self.randomize
                else self.base_scenario
            )
            self._path.set(i, sc.path)
            self._ego[:, i] = sc.ego.start.as_tuple()
            self._input[:, i] = sc.ego.initial_input
            self._object[:, i] = (*sc.object.start.as_tuple(), sc.object.speed, sc.object.turn_rate)
            self._steps[i] = 0
            self._episode_risk[i] = 0.0

    def _check_actions(self, actions: Any, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(v, omega)`` arrays ``(B,)``; raises ``ValueError`` naming the copies the Box rejects."""
        a = checks.real_array(actions, "actions", f"numbers of shape ({self.num_envs}, 2)")
        if a.shape != (self.num_envs, 2):
            raise ValueError(
                f"actions must have shape ({self.num_envs}, 2) = (v [m/s], omega [rad/s]), got {a.shape}"
            )
        ego = self.base_scenario.ego
        bad_value = ~np.isfinite(a).all(axis=1)
        v, omega = np.nan_to_num(a[:, 0]), np.nan_to_num(a[:, 1])
        outside = (v < ego.v_min - slack(ego.v_min)) | (v > ego.v_max + slack(ego.v_max))
        outside |= np.abs(omega) > ego.omega_max + slack(ego.omega_max)
        for name, bad in (("non-finite", bad_value), ("outside the action space", outside & ~bad_value)):
            bad &= active
            if bad.any():
                rows = np.flatnonzero(bad)[:5].tolist()
                raise ValueError(
                    f"actions of copies {rows} are {name}: {a[rows].tolist()} (bounds v in"
                    f" [{ego.v_min}, {ego.v_max}] m/s, |omega| <= {ego.omega_max} rad/s;"
                    " the env clips nothing)"
                )
        return v, omega

    def _risk(self, ego_state: np.ndarray, belief: Belief, idx: np.ndarray) -> np.ndarray:
        """R of ``ego_state (A, 4)`` against the beliefs of copies ``idx``; Monte Carlo draws from
        each copy's own generator, as the single env does."""
        if not isinstance(self.estimator, MonteCarloRisk):
            return np.broadcast_to(self.estimator.risk(ego_state, belief), len(idx))
        out = np.empty(len(idx))
        for j, i in enumerate(idx):
            one = dataclasses.replace(
                belief, x=belief.x[j], y=belief.y[j], theta=belief.theta[j], speed=belief.speed[j]
            )
            out[j] = self.estimator.risk(ego_state[j], one, rng=self._rngs[i])
        return out

    def _observe(self):
        s = self.base_scenario
        return observe(
            self._path,
            s.ego.v_ref,
            s.collision_distance,
            tuple(self._ego),
            tuple(self._input),
            tuple(self._object),
        )

    def _infos(self, seen: Any, risk: np.ndarray, stepped: np.ndarray) -> dict[str, Any]:
        """The single env's info keys as arrays over copies, each with an all-True ``_key`` mask."""
        n = self.num_envs
        terms = reward_terms(seen.path_error, risk, self.reward_risk_weight)
        rewards = {k: np.where(stepped, v, 0.0) for k, v in terms.items()}
        values = {
            "risk": risk,
            "cost": risk.copy(),
            "episode_risk": self._episode_risk.copy(),
            "risk_violation": risk > self.base_scenario.risk_tolerance,
            "collision": seen.collision,
            "distance": seen.distance,
            "path_error": seen.path_error,
            "lambda": seen.lam,
            "ego": np.stack((*self._ego, self._input[0]), axis=-1),
            "object": self._object[:4].T.copy(),
            "is_success": seen.goal & ~seen.collision,
        }
        ones = np.ones(n, dtype=bool)
        infos: dict[str, Any] = {}
        for key, value in values.items():
            infos[key], infos[f"_{key}"] = value, ones.copy()
        infos["rewards"] = {**rewards, **{f"_{k}": ones.copy() for k in rewards}}
        infos["_rewards"] = ones.copy()
        return infos


def _autoreset_mode(value: AutoresetMode | str) -> AutoresetMode:
    """``AutoresetMode`` from itself, its value (``"SameStep"``) or its name (``"same_step"``)."""
    if isinstance(value, AutoresetMode):
        return value
    for mode in AutoresetMode:
        if value in (mode.value, mode.name, mode.name.lower()):
            return mode
    names = [m.name.lower() for m in AutoresetMode]
    raise ValueError(f"unknown autoreset_mode {value!r}; expected an AutoresetMode or one of {names}")


def _masked(infos: dict[str, Any], mask: np.ndarray) -> dict[str, Any]:
    """A copy of vector ``infos`` whose ``_key`` masks are ``mask`` and whose entries are zero off it
    (Gymnasium's final_info form)."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        if key.startswith("_"):
            out[key] = mask.copy()
        elif isinstance(value, dict):
            out[key] = _masked(value, mask)
        else:
            out[key] = _where(mask, value, np.zeros_like(value))
    return out


def _where(mask: np.ndarray, new: Any, old: Any) -> Any:
    """Entries of ``new`` where ``mask`` (per copy), else ``old``; recurses into dicts."""
    if isinstance(new, dict):
        return {k: (_where(mask, new[k], old[k]) if not k.startswith("_") else old[k]) for k in new}
    m = mask.reshape(mask.shape + (1,) * (np.ndim(new) - 1))
    return np.where(m, new, old)
