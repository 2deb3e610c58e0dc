"""``RiskCrossing-v0``: follow a reference path while an object crosses it; every step reports
the collision risk of the paper (Tolksdorf et al., IEEE IV 2023) in ``info`` and as a cost.

The env only sequences what the rest of :mod:`risk_env` defines: the unicycle
(:mod:`risk_env.dynamics`), the path (:mod:`risk_env.path`), the object's prediction
(:mod:`risk_env.prediction`) and the risk estimators (:mod:`risk_env.risk`). Drawing lives in
:mod:`risk_env.rendering`, imported only when a render mode is set.
"""

from __future__ import annotations

import difflib
import inspect
import math
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from risk_env import checks, observation
from risk_env.checks import ACTION_TOLERANCE, slack  # noqa: F401  (ACTION_TOLERANCE: public here too)
from risk_env.ops import MATH
from risk_env.path import project
from risk_env.renderers import RENDERERS, make_renderer
from risk_env.risk import RiskEstimator, make_estimator
from risk_env.scenario import OVERRIDES, Scenario
from risk_env.transition import advance_one, observe, reward_terms
from risk_env.variations import Variations, vary

ENV_ID = "RiskCrossing-v0"
OBJECT_MOTIONS: tuple[str, ...] = ("paper", "sampled")
"""How the object moves: ``"paper"`` (deterministic unicycle) or ``"sampled"`` (one draw per step
from the prediction model)."""
"""Who draws: highway-env's graphics, the basic pygame view, or ``"auto"`` (highway-env's if installed)."""


class RiskCrossingEnv(gym.Env[np.ndarray, np.ndarray]):
    """An ego vehicle follows a reference arc while an object crosses it (paper Sec. VI-VII).

    ## Description

    The paper's case study: the ego, a unicycle with the exact arc update, should follow a
    constant-curvature path to its goal at the reference speed; an object (another unicycle with
    constant inputs) crosses the path. The object's next position and speed are uncertain: the
    prediction model (:func:`risk_env.predict`) gives truncated Gaussians around its predicted
    mean. Each step reports the collision risk ``R = E[I_C s]`` of the step just taken, with the
    estimator chosen at construction, in ``info["risk"]`` and ``info["cost"]`` (a constraint cost
    for safe RL; the risk tolerance epsilon is ``scenario.risk_tolerance``). All numbers come
    from one :class:`~risk_env.scenario.Scenario` (``env.unwrapped.scenario``).

    ## Action Space

    ``Box(low=(v_min, -omega_max), high=(v_max, omega_max), shape=(2,), float32)``, physical units:

    | index | action | unit | default bounds |
    | --- | --- | --- | --- |
    | 0 | ego speed v | m/s | [-4, 8] (``v_min``, ``v_max``; negative reverses) |
    | 1 | ego turn rate omega | rad/s | [-0.8, 0.8] (``omega_max``) |

    The env clips nothing: an action outside the Box (by more than 1e-6, relative for limits
    above 1: float32 rounding), with a NaN, of a shape other than ``(2,)`` or not of real numbers
    (bools, strings, complex numbers) raises ``ValueError``; float and int arrays, lists and
    tuples of numbers pass. The rate limits ``accel_max`` and ``omega_rate_max`` of the scenario
    are **not** enforced by the env; the MPC agents respect them themselves.

    ## Observation Space

    ``Box((15,), float32)`` with finite bounds (1e5 for positions, arc length and position
    errors, pi for headings, 1e3 for speeds and turn rates), the same for every scenario: the
    scenario rejects what could leave them within an episode. The layout and the bounds are
    :mod:`risk_env.observation` (``RiskCrossingEnv.observation_slices`` names its parts):

    | index | observation | unit |
    | --- | --- | --- |
    | 0, 1, 2 | ego pose c1, c2, theta (wrapped to [-pi, pi)) | m, m, rad |
    | 3, 4 | ego's last applied input v, omega | m/s, rad/s |
    | 5, 6, 7 | object's measured pose c1, c2, theta (wrapped) | m, m, rad |
    | 8, 9 | object's measured inputs v, omega | m/s, rad/s |
    | 10 | lambda: arc length of the ego's closest path point (goal at 0) | m |
    | 11..14 | path error e = (c1 - c1_P, c2 - c2_P, theta - theta_P, v - v_ref) at lambda | m, m, rad, m/s |

    The object is measured exactly; its uncertainty is that of its *future*.

    ## Transition

    ``step(action)`` is a fixed sequence:

    1. validate the action;
    2. the ego moves: the unicycle of :mod:`risk_env.dynamics` (the map of
       :func:`risk_env.dynamics.step`) over ``dt`` with ``(v, omega)``;
    3. the object moves. The belief ``B = predict(scenario, measurement_k, steps=1)[1]`` is made
       from the object's measurement *before* it moves. ``object_motion="paper"`` (default): the
       object follows its unicycle with the scenario's constant inputs, which is exactly B's
       mean. ``"sampled"``: its next (c1, c2, v) is one draw from B (``self.np_random``), its
       heading advances with the mean model, and the drawn v becomes its measured speed, so the
       reported risk is exactly the expected severity of what then happens;
    4. risk ``R_{k+1|k}``: B evaluated by the estimator at the ego's new state
       ``(c1, c2, theta, v)`` with v the applied speed (Monte Carlo draws from ``self.np_random``);
    5. reward terms, termination, truncation, observation, info.

    ## Rewards

    ``reward = sum(info["rewards"].values())`` with the named terms

    - ``"path_error"``: ``-||e_{k+1}||``, the norm of the path error after the step (so the
      return is minus the paper's accumulated error e_acc, without the start state's term);
    - ``"risk"``: ``-reward_risk_weight * R_{k+1|k}`` (0 by default: the risk is a cost).

    ## Starting State

    Deterministic: the ego at ``scenario.ego.start`` with ``scenario.ego.initial_input`` as its
    last input (at rest by default), the object at ``scenario.object.start`` with its constant
    inputs ``(object.speed, object.turn_rate)``. A seed only seeds ``self.np_random``.

    With ``randomize=True`` each reset draws the episode's scenario from ``self.np_random``
    (:func:`risk_env.variations.vary`: path curvature, ego start relative to the path, object
    start and speed); ``env.unwrapped.scenario`` is then the current episode's scenario and
    ``env.unwrapped.base_scenario`` the one given.

    ## Episode End

    - terminated: a collision (centre distance <= r_e + r_o), or the goal is reached (the
      closest path point has ``lambda >= lambda_g``; ``info["is_success"]`` is True when the
      goal is reached without a collision);
    - truncated: after ``scenario.max_steps`` steps (80 by default).

    Stepping on after the episode has ended raises ``gymnasium.error.ResetNeeded`` until
    ``reset`` (the batched env resets ended copies itself).

    ## Arguments

    ``gym.make("RiskCrossing-v0", uncertainty="low", risk_tolerance=0.0, risk_estimator="exact",
    object_motion="paper", reward_risk_weight=0.0, render_mode=None, renderer="auto", **overrides)``

    - ``uncertainty``: the paper's Table I preset, ``"low"`` (default), ``"medium"`` or ``"high"``;
    - ``risk_tolerance``: epsilon [J for the paper's severity]; ``info["risk_violation"]`` is
      ``risk > epsilon``;
    - ``risk_estimator``: ``"exact"`` (default), ``"monte_carlo"`` (J = ``mc_samples``),
      ``"worst_case"`` or ``"grid"`` (:data:`risk_env.ESTIMATOR_NAMES`);
    - ``object_motion``: ``"paper"`` or ``"sampled"`` (see Transition);
    - ``reward_risk_weight``: w >= 0 of the reward's risk term;
    - ``randomize``: draw each episode's scenario around the given one (see Starting State);
      ``variations``: the ranges, a :class:`risk_env.Variations`;
    - ``render_mode``: ``None``, ``"rgb_array"`` or ``"human"`` (pygame; see
      :mod:`risk_env.rendering`);
    - ``renderer``: ``"auto"`` (default: ``"highway"`` when highway-env is installed, else
      ``"basic"``), ``"highway"`` (highway-env's road and vehicle graphics with our overlays,
      :mod:`risk_env.highway.graphics`; needs ``pip install 'riskcrossing[render]'``) or ``"basic"``;
    - ``**overrides``: flat scenario parameters, :data:`risk_env.scenario.OVERRIDES`, e.g.
      ``object_speed=2.5, v_ref=3.0, severity="plastic", max_steps=60``;
    - ``scenario``: a whole :class:`~risk_env.scenario.Scenario` instead of ``uncertainty``,
      ``risk_tolerance`` and the overrides (giving both raises ``TypeError``).

    ## Info

    Returned by ``step`` (and by ``reset``, with ``risk`` 0, ``risk_violation`` False and the
    reward terms 0):

    | key | value |
    | --- | --- |
    | ``risk``, ``cost`` | R_{k+1|k} (float) |
    | ``episode_risk`` | sum of ``risk`` since ``reset`` (float): Safety-Gymnasium's per-episode cost |
    | ``risk_violation`` | ``risk > scenario.risk_tolerance`` (bool) |
    | ``collision`` | ``distance <= r_e + r_o`` (bool) |
    | ``distance`` | centre distance ego-object after the step [m] (float) |
    | ``path_error`` | e at the closest path point, ``(4,)`` float64 |
    | ``lambda`` | arc length of the closest path point [m] (float) |
    | ``ego``, ``object`` | true ``(c1, c2, theta, v)``, ``(4,)`` float64 (headings unwrapped) |
    | ``rewards`` | the named reward terms (dict of float) |
    | ``is_success`` | goal reached without a collision (bool) |

    ## Example

    >>> import gymnasium as gym
    >>> import risk_env
    >>> env = gym.make("RiskCrossing-v0", uncertainty="medium", risk_tolerance=500.0, v_ref=3.0)
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(np.array([3.0, 0.0], dtype=np.float32))
    >>> obs.shape, info["risk"] >= 0.0
    ((15,), True)

    ## Version History

    - v0: initial version; ``randomize`` and the vectorised form
      (``gym.make_vec("RiskCrossing-v0", num_envs=...)``, :mod:`risk_env.vector_env`) added.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 2.0}
    observation_slices: dict[str, slice] = observation.SLICES
    """Names of the observation's parts (:data:`risk_env.observation.SLICES`)."""

    def __init__(
        self,
        uncertainty: str | None = None,
        risk_tolerance: float | None = None,
        risk_estimator: str = "exact",
        render_mode: str | None = None,
        object_motion: str = "paper",
        reward_risk_weight: float = 0.0,
        scenario: Scenario | None = None,
        randomize: bool = False,
        variations: Variations | None = None,
        renderer: str = "auto",
        **overrides: Any,
    ) -> None:
        self.base_scenario: Scenario = _build_scenario(uncertainty, risk_tolerance, scenario, overrides)
        """The scenario given at construction (the episodes' own with ``randomize=False``)."""
        self.scenario: Scenario = self.base_scenario
        """The current episode's scenario; its ``risk_tolerance`` is the env's epsilon."""
        if variations is not None and not isinstance(variations, Variations):
            raise TypeError(f"variations must be a risk_env.Variations, got {type(variations).__name__}")
        if variations is not None and not randomize:
            raise ValueError("variations= is used only with randomize=True")
        self.randomize = checks.flag("randomize", randomize)
        self.variations: Variations = Variations() if variations is None else variations
        if object_motion not in OBJECT_MOTIONS:
            raise ValueError(f"unknown object_motion {object_motion!r}; expected one of {OBJECT_MOTIONS}")
        self.object_motion = object_motion
        weight = checks.real("reward_risk_weight", reward_risk_weight)
        if not (math.isfinite(weight) and weight >= 0.0):
            raise ValueError(f"reward_risk_weight must be finite and >= 0, got {reward_risk_weight!r}")
        self.reward_risk_weight = weight
        self.estimator: RiskEstimator = make_estimator(risk_estimator, self.scenario)
        """The risk estimator that reports ``info["risk"]``."""
        modes = self.metadata["render_modes"]
        if render_mode is not None and render_mode not in modes:
            raise ValueError(f"unknown render_mode {render_mode!r}; expected None or one of {modes}")
        self.render_mode = render_mode
        if renderer not in RENDERERS:
            raise ValueError(f"unknown renderer {renderer!r}; expected one of {RENDERERS}")
        self.renderer = renderer
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / self.scenario.dt}

        ego = self.scenario.ego
        self.action_space = spaces.Box(
            low=np.array([ego.v_min, -ego.omega_max], dtype=np.float32),
            high=np.array([ego.v_max, ego.omega_max], dtype=np.float32),
            dtype=np.float32,
        )
        high = observation.bounds()
        self.observation_space = spaces.Box(low=-high, high=high, dtype=np.float32)

        self._ego_pose: tuple[float, float, float] = self.scenario.ego.start.as_tuple()  # unwrapped
        self._ego_input: tuple[float, float] = ego.initial_input
        self._object: tuple[float, float, float, float, float] | None = None  # c1, c2, theta, v, omega
        self._steps = 0
        self._ended: str | None = None  # why the episode ended, until reset
        self._plan: np.ndarray | None = None
        self._last_risk = 0.0
        self._episode_risk = 0.0
        self._renderer: Any = None

    # ---------------------------------------------------------------- properties
    @property
    def epsilon(self) -> float:
        """The risk tolerance epsilon (``scenario.risk_tolerance``)."""
        return self.scenario.risk_tolerance

    @property
    def dt(self) -> float:
        """The sample time T [s]."""
        return self.scenario.dt

    @property
    def steps(self) -> int:
        """Steps taken in the current episode."""
        return self._steps

    @property
    def object_measurement(self) -> np.ndarray:
        """The object's current measurement ``(c1, c2, theta, v, omega)``, as :func:`predict` takes it."""
        self._require_reset()
        return np.array(self._object, dtype=float)

    @property
    def plan(self) -> np.ndarray | None:
        """The planned ego positions set by :meth:`set_plan` ``(M, 2)`` [m], or None."""
        return None if self._plan is None else self._plan.copy()

    # ---------------------------------------------------------------- gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a new episode (the scenario's start, or a drawn variation of it with
        ``randomize=True``); ``options`` takes no keys."""
        super().reset(seed=None if seed is None else checks.integer("seed", seed, minimum=0))
        if options:
            raise ValueError(f"RiskCrossing-v0 takes no reset options, got {sorted(options)}")
        if self.randomize:
            self.scenario = vary(self.base_scenario, self.np_random, self.variations)
            self.close()  # the renderer draws the previous episode's path
        s = self.scenario
        self._ego_pose = s.ego.start.as_tuple()
        self._ego_input = s.ego.initial_input
        self._object = (*s.object.start.as_tuple(), float(s.object.speed), float(s.object.turn_rate))
        self._steps = 0
        self._ended = None
        self._plan = None
        self._last_risk = 0.0
        self._episode_risk = 0.0
        obs, info, _ = self._observe(risk=0.0, stepped=False)
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        """Apply ``action = (v [m/s], omega [rad/s])`` for one sample time (see the class docstring)."""
        self._require_reset()
        if self._ended is not None:
            raise gym.error.ResetNeeded(f"the episode has ended ({self._ended}); call env.reset() to step on")
        s = self.scenario
        v, omega = self._check_action(action)
        # 1.-3. the ego moves (dynamics.step's unicycle); the object moves from its one-step
        # belief B, made from its measurement before the move; the risk R_{k+1|k} of the ego's new
        # state against B. Python floats throughout: numpy's per-call cost would dominate.
        uniforms = self.np_random.random(3).tolist() if self.object_motion == "sampled" else None
        self._ego_pose, self._object, risk = advance_one(
            s, self.estimator, self._ego_pose, (v, omega), self._object, uniforms, self.np_random
        )
        self._ego_input = (v, omega)
        self._last_risk = risk
        self._episode_risk += risk
        self._steps += 1
        # 4. reward terms, episode end, observation, info
        obs, info, goal = self._observe(risk, stepped=True)
        reward = info["rewards"]["path_error"] + info["rewards"]["risk"]
        terminated = info["collision"] or goal
        truncated = self._steps >= s.max_steps
        if terminated or truncated:
            self._ended = checks.episode_end(info["collision"], goal, self._steps, s.max_steps)
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """``"rgb_array"``: the frame ``(H, W, 3)`` uint8; ``"human"``: draw to the window."""
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human' to"
                f' gym.make("{ENV_ID}", ...)'
            )
            return None
        self._require_reset()
        if self._renderer is None:
            fps = self.metadata["render_fps"]
            self._renderer = make_renderer(
                self.renderer, self.scenario, self.render_mode, fps, self.estimator.name
            )
        ego_x, ego_y, _ = self._ego_pose
        lam = float(project(self.scenario.path, ego_x, ego_y))
        return self._renderer.render(
            ego_pose=np.array(self._ego_pose),
            ego_speed=self._ego_input[0],
            object_measurement=np.array(self._object, dtype=float),
            plan=self._plan,
            status=(
                f"k = {self._steps}  t = {self._steps * self.scenario.dt:.1f} s",
                f"risk = {self._last_risk:.4g}  (eps = {self.epsilon:g})",
                f"lambda = {lam:.1f} m",
            ),
        )

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ---------------------------------------------------------------- extras
    def set_plan(self, xy: np.ndarray | None) -> None:
        """Show a planned ego trajectory ``(M, 2)`` positions [m] in renders; None clears it.

        For benchmarks and demos only (agents read observations and never call this); the plan
        has no effect on the dynamics and is cleared by ``reset``.
        """
        if xy is None:
            self._plan = None
            return
        plan = np.array(xy, dtype=float)
        if plan.ndim != 2 or plan.shape[1] != 2 or plan.shape[0] < 1:
            raise ValueError(f"plan must have shape (M, 2) of positions [m], got {plan.shape}")
        if not np.all(np.isfinite(plan)):
            raise ValueError(f"plan has non-finite entries: {plan}")
        self._plan = plan

    # ---------------------------------------------------------------- internals
    def _require_reset(self) -> None:
        if self._object is None:
            raise gym.error.ResetNeeded("call env.reset() before env.step() or env.render()")

    def _check_action(self, action: Any) -> tuple[float, float]:
        """The action as ``(v, omega)`` floats; raises ``ValueError`` on anything the Box rejects."""
        a = checks.real_array(action, "action", "2 numbers (v [m/s], omega [rad/s])")
        if a.shape != (2,):
            raise ValueError(
                f"action must have shape (2,) = (v [m/s], omega [rad/s]), got shape {a.shape}: {action!r}"
            )
        v, omega = float(a[0]), float(a[1])
        if not (math.isfinite(v) and math.isfinite(omega)):
            raise ValueError(f"action must be finite, got (v, omega) = ({v}, {omega})")
        ego = self.scenario.ego
        if not (
            ego.v_min <= v <= ego.v_max or ego.v_min - slack(ego.v_min) <= v <= ego.v_max + slack(ego.v_max)
        ):
            raise ValueError(
                f"action v = {v} m/s lies outside [v_min, v_max] = [{ego.v_min}, {ego.v_max}]"
                " (the env clips nothing)"
            )
        if not (abs(omega) <= ego.omega_max or abs(omega) <= ego.omega_max + slack(ego.omega_max)):
            raise ValueError(
                f"action omega = {omega} rad/s lies outside [-omega_max, omega_max] ="
                f" [{-ego.omega_max}, {ego.omega_max}] (the env clips nothing)"
            )
        return v, omega

    def _observe(self, risk: float, stepped: bool) -> tuple[np.ndarray, dict[str, Any], bool]:
        """Observation, info and whether the goal is reached; the reward terms are 0 at reset."""
        s = self.scenario
        pose, obj = self._ego_pose, self._object
        seen = observe(s.path, s.ego.v_ref, s.collision_distance, pose, self._ego_input, obj, MATH)
        if stepped:
            rewards = reward_terms(seen.error_norm, risk, self.reward_risk_weight)
        else:
            rewards = {"path_error": 0.0, "risk": 0.0}
        collision, goal = seen.collision, seen.goal
        info = {
            "risk": risk,
            "cost": risk,
            "episode_risk": self._episode_risk,
            "risk_violation": risk > s.risk_tolerance,
            "collision": collision,
            "distance": seen.distance,
            "path_error": seen.path_error,
            "lambda": seen.lam,
            "ego": np.array((pose[0], pose[1], pose[2], self._ego_input[0])),
            "object": np.array(obj[:4]),
            "rewards": rewards,
            "is_success": goal and not collision,
        }
        return seen.obs, info, goal


def _build_scenario(
    uncertainty: str | None,
    risk_tolerance: float | None,
    scenario: Scenario | None,
    overrides: dict[str, Any],
) -> Scenario:
    """The env's scenario from either ``scenario`` or a preset with overrides; clear errors."""
    unknown = [name for name in overrides if name not in OVERRIDES]
    if unknown:
        known = [*OVERRIDES, *_ENV_ARGUMENTS]
        hints = []
        for name in unknown:
            close = difflib.get_close_matches(name, known, n=3)
            hints.append(f"{name!r}" + (f" (did you mean {', '.join(close)}?)" if close else ""))
        raise TypeError(
            f"RiskCrossingEnv got unknown keyword argument(s) {', '.join(hints)}. Env arguments:"
            f" {sorted(_ENV_ARGUMENTS)}; scenario parameters: {sorted(OVERRIDES)}"
        )
    if scenario is not None:
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a risk_env.Scenario, got {type(scenario).__name__}")
        given = [
            name
            for name, value in (("uncertainty", uncertainty), ("risk_tolerance", risk_tolerance))
            if value is not None
        ]
        given += sorted(overrides)
        if given:
            raise TypeError(
                f"pass either scenario= or uncertainty/risk_tolerance/scenario parameters, not both;"
                f" got scenario= and {given}. Use scenario.replace(...) to change a scenario."
            )
        return scenario
    if risk_tolerance is not None:
        overrides = {**overrides, "risk_tolerance": risk_tolerance}
    return Scenario.preset("low" if uncertainty is None else uncertainty, **overrides)


_ENV_ARGUMENTS: tuple[str, ...] = tuple(
    name
    for name in inspect.signature(RiskCrossingEnv.__init__).parameters
    if name not in ("self", "overrides")
)
