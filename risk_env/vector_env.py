"""``RiskCrossing-v0`` batched: B copies stepped at once with numpy, the risk of the whole batch in
one estimator call.

``gym.make_vec("RiskCrossing-v0", num_envs=64)`` builds it (the spec's ``vector_entry_point``);
``vectorization_mode="sync"`` or ``"async"`` builds Gymnasium's vector envs of single envs
instead. Copy i behaves exactly like ``gym.make("RiskCrossing-v0", ...)`` reset with
``seed + i``: the same arguments, its own generator drawn in the same order (for many copies
all at once, :mod:`risk_env.pcg64`), the same transition (:mod:`risk_env.transition`: numpy arrays
here, Python floats in the single env and for batches of up to :data:`SCALAR_COPIES`). Tests hold
the modes to the same numbers to 1e-12 (risks: 1e-12 in probability).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from risk_env import checks, dynamics, observation
from risk_env.checks import slack
from risk_env.env import RiskCrossingEnv
from risk_env.ops import MATH, NUMPY
from risk_env.path import PathBatch
from risk_env.pcg64 import GeneratorBatch
from risk_env.prediction import Belief, predict_step
from risk_env.risk import MonteCarloRisk
from risk_env.scenario import Scenario
from risk_env.transition import Observed, advance_one, move_object, observe, reward_terms
from risk_env.variations import DRAWS, draw
from risk_env.vector_infos import masked, parse_autoreset_mode, where


class RiskCrossingVectorEnv(VectorEnv):
    """B copies of :class:`~risk_env.env.RiskCrossingEnv` in numpy arrays.

    Takes the single env's keyword arguments (validated by building one) plus ``num_envs`` and
    ``autoreset_mode`` (Gymnasium's ``AutoresetMode``, next-step by default; ``"same_step"``
    suits stable-baselines3). Observations ``(B, 15)`` float32, actions ``(B, 2)`` in physical
    units, infos as Gymnasium's vector envs give them: every key of the single env's info as an
    array over copies, with its ``_key`` mask (one shared read-only all-True array). Draws
    nothing (``render_mode`` must be None).

    The state lives in one array ``(10, B)`` whose rows are the observation's first ten entries
    (headings unwrapped); a step computes every copy and keeps the result by mask where a copy
    was just reset (next-step autoreset), so its fixed cost is a few dozen numpy calls.
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
        mode = parse_autoreset_mode(autoreset_mode)
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

        n, s = num_envs, self.base_scenario
        self._generators = GeneratorBatch(n)
        self._path = PathBatch(np.full(n, s.path.curvature), s.path.goal)  # vary keeps the goal
        self._state = np.zeros((_STATE, n))  # observation rows 0..9, headings unwrapped
        self._spare = np.zeros((_STATE, n))
        self._start = np.array(
            (*s.ego.start.as_tuple(), *s.ego.initial_input, *s.object.start.as_tuple())
            + (s.object.speed, s.object.turn_rate)
        )
        self._steps = np.zeros(n, dtype=np.int64)
        self._episode_risk = np.zeros(n)  # sum of the risk since each copy's reset
        self._autoreset = np.zeros(n, dtype=bool)
        self._started = False
        ego = s.ego
        w_slack = slack(ego.omega_max)
        self._action_low = np.array([ego.v_min - slack(ego.v_min), -ego.omega_max - w_slack])
        self._action_high = np.array([ego.v_max + slack(ego.v_max), ego.omega_max + w_slack])
        self._mask = np.ones(n, dtype=bool)
        self._mask.setflags(write=False)
        self._never = np.zeros(n, dtype=bool)
        self._never.setflags(write=False)
        self.scalar_copies = SCALAR_COPIES
        """Batches of up to this many copies step one by one in Python floats (0: always numpy)."""

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
        for i in np.flatnonzero(mask).tolist():
            if seeds[i] is not None or self._generators.generators[i] is None:
                self._generators.seed(i, seeds[i])
        self._reset_copies(mask)
        self._started = True
        self._autoreset[mask] = False
        seen = self._observe()
        return seen.obs, self._infos(seen, np.zeros(n), self._never)

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every copy with ``actions (B, 2)`` = (v [m/s], omega [rad/s]) per copy."""
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        n, s = self.num_envs, self.base_scenario
        mode = self.metadata["autoreset_mode"]
        a = self._actions(actions)
        active = None  # None: every copy steps
        if self._autoreset.any():
            if mode == AutoresetMode.DISABLED:
                raise gym.error.ResetNeeded(
                    f"copies {np.flatnonzero(self._autoreset).tolist()} have ended; reset them with"
                    " options={'reset_mask': ...} (autoreset_mode is disabled)"
                )
            self._reset_copies(self._autoreset)  # next-step autoreset: these copies only reset
            active = ~self._autoreset
        self._check_actions(a, active)
        if active is not None:  # the reset copies are computed too, on a harmless input, and kept
            a[~active] = 0.0
        if n <= self.scalar_copies:
            risk = self._advance_one_by_one(a, active)
        else:
            risk = self._advance(a, active)
        self._episode_risk += risk  # 0 where a copy did not step
        # 4. reward terms, episode end, observation, info
        seen = self._observe()
        stepped = self._mask if active is None else active
        infos = self._infos(seen, risk, stepped)
        rewards = infos["rewards"]["path_error"] + infos["rewards"]["risk"]  # 0 where not stepped
        terminated = seen.collision | seen.goal
        truncated = self._steps >= s.max_steps
        if active is not None:
            terminated &= active
            truncated &= active
        done = terminated | truncated
        obs = seen.obs
        if mode == AutoresetMode.SAME_STEP and done.any():
            final_obs = np.full(n, None, dtype=object)
            for i in np.flatnonzero(done):
                final_obs[i] = obs[i]
            infos["final_info"] = masked(infos, done)
            infos["_final_info"] = done.copy()
            infos["final_obs"], infos["_final_obs"] = final_obs, done.copy()
            self._reset_copies(done)
            reset_seen = self._observe()
            obs = reset_seen.obs
            fresh = self._infos(reset_seen, np.zeros(n), self._never)
            infos.update({k: where(done, fresh[k], infos[k]) for k in fresh if not k.startswith("_")})
        else:
            self._autoreset = done
        return obs, rewards, terminated, truncated, infos

    def _advance(self, a: np.ndarray, active: np.ndarray | None) -> np.ndarray:
        """Steps 1-3 of the transition for every copy at once (numpy); the new state replaces
        the old where a copy steps. Returns R ``(B,)``, 0 where a copy did not step."""
        s, state = self.base_scenario, self._state
        v, omega = a[:, 0], a[:, 1]
        # 1. the ego moves
        new = self._spare  # the state after the step, written over the one before last
        new[0], new[1], new[2] = dynamics.unicycle_step(state[0], state[1], state[2], v, omega, s.dt, NUMPY)
        new[3], new[4] = v, omega
        # 2. the object moves; B = its one-step belief from the measurement before the move
        measurement = (state[5], state[6], state[7], state[8], state[9])
        belief = predict_step(s, measurement, 1, NUMPY)
        uniforms = self._generators.random(3, active) if self.object_motion == "sampled" else None
        new[5], new[6], new[7], new[8], new[9] = move_object(belief, measurement, uniforms, NUMPY)
        # 3. the risk R_{k+1|k} of the ego's new state against B
        risk = self._risk(new[0:4].T, belief, active)
        if active is None:
            self._state, self._spare = new, state
            self._steps += 1
        else:
            np.copyto(state, new, where=active)
            self._steps += active
        return risk

    def _advance_one_by_one(self, a: np.ndarray, active: np.ndarray | None) -> np.ndarray:
        """:meth:`_advance` for a few copies: each in Python floats by the single env's own
        :func:`~risk_env.transition.advance_one`, cheaper than numpy's per-call cost."""
        s, rows, generators = self.base_scenario, self._state.T.tolist(), self._generators
        draws = generators.random(3, active).tolist() if self.object_motion == "sampled" else None
        risk = [0.0] * self.num_envs
        for i, (v, omega) in enumerate(a.tolist()):
            if active is not None and not active[i]:
                continue
            row, rng = rows[i], generators.borrow(i)  # Monte Carlo draws from it
            uniforms = None if draws is None else draws[i]
            pose, moved, risk[i] = advance_one(
                s, self.estimator, row[0:3], (v, omega), row[5:10], uniforms, rng
            )
            generators.give_back(i)
            rows[i] = [*pose, v, omega, *moved]
            self._steps[i] += 1
        self._state[:] = np.array(rows).T
        return np.array(risk)

    def close_extras(self, **kwargs: Any) -> None:
        self.template.close()

    # ---------------------------------------------------------------- internals
    def _reset_copies(self, mask: np.ndarray) -> None:
        """Put the copies in ``mask`` at their episode's start (drawing it when randomising)."""
        if not self.randomize:
            self._state[:, mask] = self._start[:, None]
            self._steps[mask] = 0
            self._episode_risk[mask] = 0.0
            return
        index = np.flatnonzero(mask)
        # each copy's own generator, DRAWS uniforms on [-1, 1) as vary takes them (bit for bit)
        u = self._generators.random_at(DRAWS, index) * 2.0 - 1.0
        if len(index) <= self.scalar_copies:  # a few copies: each in Python floats
            starts = [draw(self.base_scenario, row, self.variations, MATH) for row in u.tolist()]
            curvature, ego, obj, speed = (np.array(field) for field in zip(*starts, strict=True))
            ego, obj = ego.T, obj.T
        else:
            curvature, ego, obj, speed = draw(self.base_scenario, u.T, self.variations, NUMPY)
        self._path.curvature[index] = curvature
        state = self._state
        state[0:3, index] = ego
        state[3:5, index] = self._start[3:5, None]
        state[5:8, index] = obj
        state[8, index] = speed
        state[9, index] = self._start[9]
        self._steps[index] = 0
        self._episode_risk[index] = 0.0

    def _actions(self, actions: Any) -> np.ndarray:
        """``actions`` as a new float array ``(B, 2)``; raises ``ValueError`` on a wrong shape."""
        expected = f"numbers of shape ({self.num_envs}, 2)"
        a = np.array(checks.real_array(actions, "actions", expected), dtype=float)  # a copy: changed later
        if a.shape != (self.num_envs, 2):
            raise ValueError(
                f"actions must have shape ({self.num_envs}, 2) = (v [m/s], omega [rad/s]), got {a.shape}"
            )
        return a

    def _check_actions(self, a: np.ndarray, active: np.ndarray | None) -> None:
        """Raise ``ValueError`` naming the stepping copies whose actions the Box rejects."""
        inside = (a >= self._action_low) & (a <= self._action_high)  # False for NaN
        if inside.all():
            return
        bad_rows = ~inside.all(axis=1)
        if active is not None:
            bad_rows &= active
        if not bad_rows.any():
            return
        ego = self.base_scenario.ego
        non_finite = ~np.isfinite(a).all(axis=1)
        for name, bad in (("non-finite", non_finite), ("outside the action space", ~non_finite)):
            bad &= bad_rows
            if bad.any():
                rows = np.flatnonzero(bad)[:5].tolist()
                raise ValueError(
                    f"actions of copies {rows} are {name}: {a[rows].tolist()} (bounds v in"
                    f" [{ego.v_min}, {ego.v_max}] m/s, |omega| <= {ego.omega_max} rad/s;"
                    " the env clips nothing)"
                )

    def _risk(self, ego_state: np.ndarray, belief: Belief, active: np.ndarray | None) -> np.ndarray:
        """R of ``ego_state (B, 4)`` against the beliefs ``(B,)``, 0 where a copy did not step;
        Monte Carlo draws from each stepping copy's own generator, as the single env does."""
        if not isinstance(self.estimator, MonteCarloRisk):
            risk = np.broadcast_to(self.estimator.risk(ego_state, belief), (self.num_envs,))
            return risk.copy() if active is None else np.where(active, risk, 0.0)
        risk = np.zeros(self.num_envs)
        copies = range(self.num_envs) if active is None else np.flatnonzero(active).tolist()
        for i in copies:
            one = dataclasses.replace(
                belief, x=belief.x[i], y=belief.y[i], theta=belief.theta[i], speed=belief.speed[i]
            )
            risk[i] = self.estimator.risk(ego_state[i], one, rng=self._generators.borrow(i))
            self._generators.give_back(i)
        return risk

    def _observe(self) -> Observed:
        s, state = self.base_scenario, self._state
        if self.num_envs <= self.scalar_copies:  # each copy in Python floats, then stacked
            goal, rows = s.path.goal, state.T.tolist()
            seen = [
                observe(PathBatch(k, goal), s.ego.v_ref, s.collision_distance, r[0:3], r[3:5], r[5:10], MATH)
                for k, r in zip(self._path.curvature.tolist(), rows, strict=True)
            ]
            return Observed(*(np.array(field) for field in zip(*seen, strict=True)))
        return observe(
            self._path,
            s.ego.v_ref,
            s.collision_distance,
            (state[0], state[1], state[2]),
            (state[3], state[4]),
            (state[5], state[6], state[7], state[8], state[9]),
            NUMPY,
        )

    def _infos(self, seen: Observed, risk: np.ndarray, stepped: np.ndarray) -> dict[str, Any]:
        """The single env's info keys as arrays over copies, each with the all-True ``_key`` mask."""
        terms = reward_terms(seen.error_norm, risk, self.reward_risk_weight)
        if stepped is not self._mask:
            terms = {k: np.where(stepped, v, 0.0) for k, v in terms.items()}
        state, mask = self._state, self._mask
        return {
            "risk": risk,
            "_risk": mask,
            "cost": risk.copy(),
            "_cost": mask,
            "episode_risk": self._episode_risk.copy(),
            "_episode_risk": mask,
            "risk_violation": risk > self.base_scenario.risk_tolerance,
            "_risk_violation": mask,
            "collision": seen.collision,
            "_collision": mask,
            "distance": seen.distance,
            "_distance": mask,
            "path_error": seen.path_error,
            "_path_error": mask,
            "lambda": seen.lam,
            "_lambda": mask,
            "ego": state[0:4].T.copy(),
            "_ego": mask,
            "object": state[5:9].T.copy(),
            "_object": mask,
            "is_success": seen.goal & ~seen.collision,
            "_is_success": mask,
            "rewards": {**terms, **{f"_{k}": mask for k in terms}},
            "_rewards": mask,
        }


SCALAR_COPIES = 7
"""Up to this many copies, a batch step runs each copy through the single env's float code (~25 us
a copy): numpy's fixed cost (some 250 calls of ~0.7 us on tiny arrays) exceeds a few copies' cost.
Measured crossover: about 8 copies."""
_STATE = observation.PROGRESS
"""Rows of the batched state: the observation's entries before lambda."""
