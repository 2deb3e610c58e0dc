"""``RiskCrossing-v0`` batched: B copies stepped at once with numpy, the risk of the whole batch in
one estimator call; ``gym.make_vec("RiskCrossing-v0", num_envs=64)`` builds it.

Copy i behaves exactly like ``gym.make("RiskCrossing-v0", ...)`` reset with ``seed + i``: the same
arguments, its own generator drawn in the same order (for many copies all at once,
:mod:`risk_env.envs.pcg64`), the same transition (:mod:`risk_env.envs.transition`: numpy arrays here,
Python floats in the single env and for batches of up to :data:`SCALAR_COPIES`). Tests hold the
modes to the same numbers to 1e-12 (risks: 1e-12 in probability).
"""

from __future__ import annotations

import dataclasses
from itertools import chain
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from risk_env import checks
from risk_env.checks import slack
from risk_env.envs.env import RiskCrossingEnv
from risk_env.envs.pcg64 import MAX_DRAWS, GeneratorBatch
from risk_env.envs.transition import Observed, advance_one, move_object, observe, reward_terms
from risk_env.envs.variations import draw, draw_count
from risk_env.envs.vector_infos import infos, masked, parse_autoreset_mode, where
from risk_env.models import dynamics
from risk_env.models.ops import MATH, NUMPY
from risk_env.models.path import PathBatch
from risk_env.prediction.belief import Belief, predict_step
from risk_env.risk.estimators import MonteCarloRisk
from risk_env.risk.total_risk import total
from risk_env.scenario.scenario import Scenario


class RiskCrossingVectorEnv(VectorEnv):
    """B copies of :class:`~risk_env.envs.env.RiskCrossingEnv` in numpy arrays.

    Takes the single env's keyword arguments (validated by building one) plus ``num_envs`` and
    ``autoreset_mode`` (Gymnasium's ``AutoresetMode``, next-step by default; ``"same_step"``
    suits stable-baselines3). Observations ``(B, 10 + 6 K)`` float32, actions ``(B, 2)`` in
    physical units, infos as Gymnasium's vector envs give them: every key of the single env's info
    as an array over copies (``risk_terms`` ``(B, M)``, ``objects`` ``(B, M, 4)``), with its
    ``_key`` mask (one shared read-only all-True array). Draws nothing; the paper's prediction only.

    The state lives in one array ``(5 + 5 M, B)``: the ego's pose and last input, then each of the
    M objects' measurement (headings unwrapped); with ``Variations(object_count=True)`` a mask
    ``(M, B)`` says which objects cross in each copy's episode. A step computes every copy and
    keeps the result by mask where a copy was just reset (next-step autoreset), so its fixed cost
    is a few dozen numpy calls per object.
    """

    def __init__(
        self,
        num_envs: int = 1,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        num_envs = checks.integer("num_envs", num_envs, minimum=1)
        mode = parse_autoreset_mode(autoreset_mode)
        template = RiskCrossingEnv(**kwargs)  # the single env validates every argument
        for name, given in (("render_mode", render_mode), ("predictor", template.predictor)):
            if given is not None:  # neither is batched: the single envs do it
                raise ValueError(
                    f"the batched RiskCrossing-v0 takes no {name} (got {given!r}); use"
                    " gym.make_vec(..., vectorization_mode='sync') or gym.make"
                )
        self.template = template
        self.base_scenario: Scenario = template.base_scenario
        self.estimators = template.estimators
        self.object_slots = template.object_slots
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
        self._objects = len(s.objects)
        rows = 5 + 5 * self._objects
        self._state = np.zeros((rows, n))  # ego pose, input; each object's measurement (unwrapped)
        self._spare = np.zeros((rows, n))
        self._start = np.array(
            [*s.ego.start.as_tuple(), *s.ego.initial_input]
            + [x for o in s.objects for x in (*o.start.as_tuple(), o.speed, o.turn_rate)]
        )
        self._uncertainties, self._radii = s.uncertainties, s.collision_distances
        counted = self.randomize and self.variations.object_count
        self._present = np.ones((self._objects, n), dtype=bool) if counted else None
        """Which objects cross in each copy's episode ``(M, B)``; None: all, always."""
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
        self._no_terms = np.zeros((len(s.objects), n))
        self._no_terms.setflags(write=False)
        self._all_present = np.ones((n, len(s.objects)), dtype=bool)
        self._all_present.setflags(write=False)
        self._all_counts = [len(s.objects)] * n
        self.scalar_copies = SCALAR_COPIES
        """Batches of up to this many copies step one by one in Python floats (0: always numpy)."""

    @property
    def epsilon(self) -> float:
        r"""The risk tolerance $\epsilon$ of every copy."""
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
        return seen.obs, self._infos(seen, self._no_terms, self._never, self._no_terms[0])

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        r"""Step every copy with ``actions (B, 2)`` = ($v$ [m/s], $\omega$ [rad/s]) per copy."""
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        n, s = self.num_envs, self.base_scenario
        mode = self.metadata["autoreset_mode"]
        a = checks.batch_actions(actions, self.num_envs)
        active = None  # None: every copy steps
        if self._autoreset.any():
            if mode == AutoresetMode.DISABLED:
                raise gym.error.ResetNeeded(
                    f"copies {np.flatnonzero(self._autoreset).tolist()} have ended; reset them with"
                    " options={'reset_mask': ...} (autoreset_mode is disabled)"
                )
            self._reset_copies(self._autoreset)  # next-step autoreset: these copies only reset
            active = ~self._autoreset
        checks.batch_actions_inside(a, self._action_low, self._action_high, self.base_scenario.ego, active)
        a[:, 1] = dynamics.turn_limit(s.ego.curvature_max, a[:, 1], a[:, 0])  # turns only while moving
        if active is not None:  # the reset copies are computed too, on a harmless input, and kept
            a[~active] = 0.0
        if n <= self.scalar_copies:
            terms = self._advance_one_by_one(a, active)
        else:
            terms = self._advance(a, active)
        risk = total(terms)  # R = sum_i R_i (risk_env.risk.total_risk)
        self._episode_risk += risk  # 0 where a copy did not step
        # 4. reward terms, episode end, observation, info
        seen = self._observe()
        stepped = self._mask if active is None else active
        infos = self._infos(seen, terms, stepped, risk)
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
            fresh = self._infos(reset_seen, self._no_terms, self._never, self._no_terms[0])
            infos.update({k: where(done, fresh[k], infos[k]) for k in fresh if not k.startswith("_")})
        else:
            self._autoreset = done
        return obs, rewards, terminated, truncated, infos

    def _advance(self, a: np.ndarray, active: np.ndarray | None) -> np.ndarray:
        """Steps 1-3 of the transition for every copy at once (numpy); the new state replaces
        the old where a copy steps. Returns the terms $R_i$ ``(M, B)``, 0 where a copy did not step
        or object i is absent."""
        s, state = self.base_scenario, self._state
        v, omega = a[:, 0], a[:, 1]
        # 1. the ego moves
        new = self._spare  # the state after the step, written over the one before last
        new[0], new[1], new[2] = dynamics.unicycle_step(state[0], state[1], state[2], v, omega, s.dt, NUMPY)
        new[3], new[4] = v, omega
        # 2. each object moves; B_i = its one-step belief from the measurement before the move
        beliefs = []
        for i in range(self._objects):
            rows = slice(5 + 5 * i, 10 + 5 * i)
            measurement = tuple(state[rows])
            belief = predict_step(s, measurement, 1, NUMPY, self._uncertainties[i])
            uniforms = None
            if self.object_motion == "sampled":
                uniforms = self._generators.random(3, self._drawing(i, active))
            new[rows] = move_object(belief, measurement, uniforms, NUMPY)
            beliefs.append(belief)
        # 3. the terms R_i of the ego's new state against each B_i
        terms = self._risk(new[0:4].T, beliefs, active)
        if active is None:
            self._state, self._spare = new, state
            self._steps += 1
        else:
            np.copyto(state, new, where=active)
            self._steps += active
        return terms

    def _drawing(self, i: int, active: np.ndarray | None) -> np.ndarray | None:
        """The copies that step with object i present (None: all)."""
        if self._present is None:
            return active
        return self._present[i] if active is None else active & self._present[i]

    def _advance_one_by_one(self, a: np.ndarray, active: np.ndarray | None) -> np.ndarray:
        """:meth:`_advance` for a few copies: each in Python floats by the single env's own
        :func:`~risk_env.envs.transition.advance_one`, cheaper than numpy's per-call cost."""
        s, rows, generators = self.base_scenario, self._state.T.tolist(), self._generators
        counts, count = self._counts(), self._objects
        draws = None
        if self.object_motion == "sampled":  # each copy's 3 uniforms per present object, in order
            if count == 1 and self._present is None:
                per_object = [generators.random(3, active).tolist()]
            else:
                per_object = [generators.random(3, self._drawing(i, active)).tolist() for i in range(count)]
            draws = per_object[0]
            if count > 1:
                draws = [
                    [u for i in range(counts[j]) for u in per_object[i][j]] for j in range(self.num_envs)
                ]
        terms = [[0.0] * self.num_envs for _ in range(count)]
        for j, (v, omega) in enumerate(a.tolist()):
            if active is not None and not active[j]:
                continue
            row, rng, m = rows[j], generators.borrow(j), counts[j]  # Monte Carlo draws from rng
            objects = [row[5:10]] if m == 1 else [row[5 + 5 * i : 10 + 5 * i] for i in range(m)]
            uniforms = None if draws is None else draws[j]
            pose, moved, risks = advance_one(
                s, self.estimators, self._uncertainties, row[0:3], (v, omega), objects, uniforms, rng
            )
            generators.give_back(j)
            row[: 5 + 5 * m] = [*pose, v, omega, *chain.from_iterable(moved)]
            for i, risk in enumerate(risks):
                terms[i][j] = risk
            self._steps[j] += 1
        self._state[:] = np.array(rows).T
        return np.array(terms)

    def _counts(self) -> list[int]:
        """How many objects (the first ones) cross in each copy's episode."""
        if self._present is None:
            return self._all_counts
        return self._present.sum(axis=0).tolist()

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
        base = self.base_scenario
        # each copy's own generator, the uniforms on [-1, 1) as vary takes them (bit for bit)
        count = draw_count(base, self.variations)
        u = np.concatenate(
            [
                self._generators.random_at(min(MAX_DRAWS, count - k), index)
                for k in range(0, count, MAX_DRAWS)
            ],
            axis=1,
        )
        u = u * 2.0 - 1.0
        if len(index) <= self.scalar_copies:  # a few copies: each in Python floats
            starts = [draw(base, row, self.variations, MATH) for row in u.tolist()]
            curvature = np.array([start.curvature for start in starts])
            ego = np.array([start.ego for start in starts]).T
            objects = np.array([start.objects for start in starts]).transpose(1, 2, 0)  # (M, 4, n)
            counts = None if self._present is None else np.array([start.count for start in starts])
        else:
            start = draw(base, u.T, self.variations, NUMPY)
            curvature, ego, counts = start.curvature, np.array(start.ego), start.count
            objects = np.array([np.broadcast_arrays(*o) for o in start.objects])  # (M, 4, n)
        self._path.curvature[index] = curvature
        state = self._state
        state[0:3, index] = ego
        state[3:5, index] = self._start[3:5, None]
        for i in range(self._objects):
            state[5 + 5 * i : 9 + 5 * i, index] = objects[i]
            state[9 + 5 * i, index] = self._start[9 + 5 * i]
        if counts is not None:
            self._present[:, index] = np.arange(self._objects)[:, None] < counts[None, :]
        self._steps[index] = 0
        self._episode_risk[index] = 0.0

    def _risk(self, ego_state: np.ndarray, beliefs: list[Belief], active: np.ndarray | None) -> np.ndarray:
        """The terms $R_i$ ``(M, B)`` of ``ego_state (B, 4)`` against the beliefs ``(B,)`` of each
        object, 0 where a copy did not step or the object is absent; Monte Carlo draws from each
        stepping copy's own generator, object by object, as the single env does."""
        terms = np.zeros((self._objects, self.num_envs))
        for i, (estimator, belief) in enumerate(zip(self.estimators, beliefs, strict=True)):
            drawing = self._drawing(i, active)
            if not isinstance(getattr(estimator, "inner", estimator), MonteCarloRisk):
                risk = estimator.risk(ego_state, belief)
                terms[i] = risk if drawing is None else np.where(drawing, risk, 0.0)
                continue
            copies = range(self.num_envs) if drawing is None else np.flatnonzero(drawing).tolist()
            for j in copies:
                one = dataclasses.replace(
                    belief, x=belief.x[j], y=belief.y[j], theta=belief.theta[j], speed=belief.speed[j]
                )
                terms[i, j] = estimator.risk(ego_state[j], one, rng=self._generators.borrow(j))
                self._generators.give_back(j)
        return terms

    def _observe(self) -> Observed:
        s, state, slots = self.base_scenario, self._state, self.object_slots
        v_ref, radii = s.ego.v_ref, self._radii
        if self.num_envs <= self.scalar_copies:  # each copy in Python floats, then stacked
            goal, rows, counts = s.path.goal, state.T.tolist(), self._counts()
            seen = [
                observe(
                    PathBatch(k, goal),
                    v_ref,
                    radii,
                    r[0:3],
                    r[3:5],
                    [r[5:10]] if m == 1 else [r[5 + 5 * i : 10 + 5 * i] for i in range(m)],
                    slots,
                    None,
                    MATH,
                )
                for k, r, m in zip(self._path.curvature.tolist(), rows, counts, strict=True)
            ]
            return Observed(*(np.array(field) for field in zip(*seen, strict=True)))
        objects = [tuple(state[5 + 5 * i : 10 + 5 * i]) for i in range(self._objects)]
        present = None if self._present is None else list(self._present)
        ego = (state[0], state[1], state[2])
        return observe(self._path, v_ref, radii, ego, (state[3], state[4]), objects, slots, present, NUMPY)

    def _infos(
        self, seen: Observed, terms: np.ndarray, stepped: np.ndarray, risk: np.ndarray
    ) -> dict[str, Any]:
        """The single env's info keys as arrays over copies (:func:`risk_env.envs.vector_infos.infos`),
        from the terms $R_i$ ``(M, B)`` and their sum ``risk``."""
        rewards = reward_terms(seen.error_norm, risk, self.reward_risk_weight)
        if stepped is not self._mask:
            rewards = {k: np.where(stepped, v, 0.0) for k, v in rewards.items()}
        return infos(
            seen,
            risk,
            terms,
            self._episode_risk,
            self._state,
            self._all_present if self._present is None else self._present.T.copy(),
            rewards,
            self.base_scenario.risk_tolerance,
            self._mask,
        )


SCALAR_COPIES = 7
"""Up to this many copies, a batch step runs each copy through the single env's float code (~25 us a
copy): numpy's fixed cost (~250 calls of ~0.7 us) exceeds a few copies' cost (measured crossover: ~8)."""
