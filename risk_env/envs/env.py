"""``RiskCrossing-v0`` (:class:`RiskCrossingEnv`): the sequence of a step over what the rest of
:mod:`risk_env` defines (models, prediction, risk); drawing in :mod:`risk_env.render`."""

from __future__ import annotations

import inspect
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from risk_env import checks, observation
from risk_env.envs import arguments
from risk_env.envs.transition import advance_one, applied_action, view
from risk_env.envs.variations import Variations, vary
from risk_env.prediction.predictors import Predictor
from risk_env.render.renderers import RENDERERS
from risk_env.render.view import EnvView
from risk_env.risk.estimators import RiskEstimator
from risk_env.risk.total_risk import make_estimators, total
from risk_env.scenario.scenario import Scenario

ENV_ID = "RiskCrossing-v0"
OBJECT_MOTIONS: tuple[str, ...] = ("paper", "sampled")
"""How the objects move: ``"paper"`` (their unicycles) or ``"sampled"`` (drawn from the prediction)."""


class RiskCrossingEnv(gym.Env[np.ndarray, np.ndarray]):
    r"""An ego vehicle follows a reference arc while road users cross it (paper Sec. VI-VII).

    ## Description

    The paper's case study: the ego, a unicycle with the exact arc update, should follow a
    constant-curvature path to its goal at the reference speed; objects (other unicycles with
    constant inputs: the paper's one by default, several with ``scene=`` or ``objects=``) cross
    the path. Their next positions and speeds are uncertain: the prediction model
    (:func:`risk_env.predict`) gives truncated Gaussians around each predicted mean. Each step
    reports the collision risk of the step just taken, $R = \sum_i R_i$ with
    $R_i = E[I_{C,i} s_i]$ of object $i$ (by linearity of expectation exactly the step's expected
    total harm, :mod:`risk_env.risk.total_risk`), with the estimator chosen at construction, in
    ``info["risk"]`` and ``info["cost"]`` (a constraint cost for safe RL; the risk tolerance
    $\epsilon$ is ``scenario.risk_tolerance``), and each object's term in ``info["risk_terms"]``.
    All numbers come from one :class:`~risk_env.scenario.scenario.Scenario` (``env.unwrapped.scenario``).

    ## Action Space

    ``Box(low=(v_min, -omega_max), high=(v_max, omega_max), shape=(2,), float32)``, physical units:

    | index | action | unit | default bounds |
    | --- | --- | --- | --- |
    | 0 | ego speed $v$ | m/s | [-4, 8] (``v_min``, ``v_max``; negative reverses) |
    | 1 | ego turn rate $\omega$ | rad/s | [-0.8, 0.8] (``omega_max``) |

    The env clips nothing: an action outside the Box (by more than 1e-6, relative for limits
    above 1: float32 rounding), with a NaN, of a shape other than ``(2,)`` or not of real numbers
    (bools, strings, complex numbers) raises ``ValueError``; float and int arrays, lists and
    tuples of numbers pass. The rate limits ``accel_max`` and ``omega_rate_max`` of the scenario
    are **not** enforced by the env; the MPC agents respect them themselves.

    ## Observation Space

    ``Box((10 + 6 K,), float32)``, $K$ the number of object slots (``object_slots``, fixed at
    construction; by default one per object of the scenario: 16 entries for the paper's scene),
    with finite bounds (1e5 for positions, arc length and position errors, $\pi$ for headings, 1e3
    for speeds and turn rates, [0, 1] for the flags), the same for every scenario: the scenario
    rejects what could leave them within an episode. The layout is :mod:`risk_env.observation`
    (read it with :func:`risk_env.observation.split`):

    | index | observation | unit |
    | --- | --- | --- |
    | 0, 1, 2 | ego pose $c_1, c_2, \theta$ (wrapped to $[-\pi, \pi)$) | m, m, rad |
    | 3, 4 | ego's last applied input $v, \omega$ | m/s, rad/s |
    | 5 | $\lambda$: arc length of the ego's closest path point (goal at 0) | m |
    | 6..9 | path error $e$ at $\lambda$ (below) | m, m, rad, m/s |
    | 10 + 6 i | slot $i$'s presence flag: 1.0 object $i$ is there, 0.0 absent (the slot all zeros) | - |
    | 11 + 6 i .. 13 + 6 i | object $i$'s measured pose $c_1, c_2, \theta$ (wrapped) | m, m, rad |
    | 14 + 6 i, 15 + 6 i | object $i$'s measured inputs $v, \omega$ | m/s, rad/s |

    The path error at $\lambda$ is $e = (c_1 - c_{1,P}, c_2 - c_{2,P}, \theta - \theta_P, v - v_{ref})$.
    Object $i$ of the scenario fills slot $i$; slots beyond the episode's objects are absent. The
    objects are measured exactly; their uncertainty is that of their *future*.

    ## Transition

    ``step(action)`` is a fixed sequence:

    1. validate the action;
    2. the ego moves: the unicycle of :mod:`risk_env.models.dynamics` (the map of
       :func:`risk_env.models.dynamics.step`) over ``dt`` with $(v, \omega)$;
    3. each object moves. Its belief $B_i$, ``predict(scenario, measurement_i, steps=1)[1]`` (with
       its own uncertainty; a ``predictor``'s mixture at step 1 instead, its risk
       $\sum_m w_m R_m$), is made from its measurement *before* it moves.
       ``object_motion="paper"`` (default): it follows its unicycle with its constant inputs,
       which is exactly $B_i$'s mean. ``"sampled"``: its next $(c_1, c_2, v)$ is one draw from $B_i$
       (``self.np_random``: 3 uniforms per object, in order), its heading advances with the mean
       model, and the drawn $v$ becomes its measured speed, so the reported risk is exactly the
       expected severity of what then happens;
    4. risk $R_{k+1|k} = \sum_i R_i$: each $B_i$ evaluated by its estimator (radius $r_e + r_{o,i}$,
       its mass in the severity) at the ego's new state $(c_1, c_2, \theta, v)$ with $v$ the applied
       speed (Monte Carlo draws from ``self.np_random``, object by object);
    5. reward terms, termination, truncation, observation, info.

    ## Rewards

    ``reward = sum(info["rewards"].values())`` with the named terms

    - ``"path_error"``: $-\|e_{k+1}\|$, the norm of the path error after the step (so the
      return is minus the paper's accumulated error ``e_acc``, without the start state's term);
    - ``"risk"``: $-w R_{k+1|k}$, $w$ = ``reward_risk_weight`` (0 by default: the risk is a cost).

    ## Starting State

    Deterministic: the ego at ``scenario.ego.start`` with ``scenario.ego.initial_input`` as its
    last input (at rest by default), each object at its ``start`` with its constant inputs
    ``(speed, turn_rate)``. A seed only seeds ``self.np_random``.

    With ``randomize=True`` each reset draws the episode's scenario from ``self.np_random``
    (:func:`risk_env.envs.variations.vary`: path curvature, ego start relative to the path, each
    object's start and speed; with ``Variations(object_count=True)`` also how many objects cross);
    ``env.unwrapped.scenario`` is then the current episode's scenario and
    ``env.unwrapped.base_scenario`` the one given.

    ## Episode End

    - terminated: a collision (some object's centre within $r_e + r_{o,i}$), or the goal is reached
      (the closest path point has $\lambda \ge \lambda_g$; ``info["is_success"]`` is True when the
      goal is reached without a collision);
    - truncated: after ``scenario.max_steps`` steps (80 by default).

    Stepping on after the episode has ended raises ``gymnasium.error.ResetNeeded`` until
    ``reset`` (the batched env resets ended copies itself).

    ## Arguments

    - ``uncertainty``: the paper's Table I preset, ``"low"`` (default), ``"medium"`` or ``"high"``;
    - ``risk_tolerance``: $\epsilon$ [J for the paper's severity]; ``risk_violation`` is $R > \epsilon$;
    - ``risk_estimator``: ``"exact"`` (default), ``"monte_carlo"`` ($J$ = ``mc_samples``),
      ``"worst_case"`` or ``"grid"`` (:data:`risk_env.ESTIMATOR_NAMES`), one per object;
    - ``object_motion``: ``"paper"`` or ``"sampled"`` (see Transition);
    - ``reward_risk_weight``: $w \ge 0$ of the reward's risk term;
    - ``scene``: which road users cross, :data:`risk_env.SCENE_NAMES` (:mod:`risk_env.scenario.scenes`):
      ``"paper"`` (default, its one object), ``"two_crossing"`` (a second one crossing from the
      other side), ``"four_crossing"``; the ``objects=[...]`` override gives any list instead;
    - ``object_slots``: $K$, the observation's object slots (default: the scenario's number of
      objects; fewer raises);
    - ``predictor``: the objects' one-step beliefs: ``None`` or ``"constant"`` (default, the
      paper's) or any :class:`risk_env.prediction.Predictor` (its mixture's risk; see Transition);
    - ``randomize``: draw each episode's scenario around the given one (see Starting State);
      ``variations``: the ranges, a :class:`risk_env.Variations`;
    - ``render_mode``: ``None``, ``"rgb_array"`` or ``"human"`` (pygame; see
      :mod:`risk_env.render.rendering`);
    - ``renderer``: ``"auto"`` (default: ``"highway"`` when highway-env is installed, else
      ``"basic"``), ``"highway"`` (highway-env's road and vehicle graphics with our overlays,
      :mod:`risk_env.highway.graphics`; needs ``pip install 'riskcrossing[render]'``) or ``"basic"``;
    - ``**overrides``: flat scenario parameters, :data:`risk_env.scenario.scenario.OVERRIDES`, e.g.
      ``object_speed=2.5`` (the first object), ``objects=[{"start": (25, 32, -1.57), "speed":
      2.5}, ...]``, ``v_ref=3.0, severity="plastic", max_steps=60``;
    - ``scenario``: a whole :class:`~risk_env.scenario.scenario.Scenario` instead of ``uncertainty``,
      ``risk_tolerance``, ``scene`` and the overrides (giving both raises ``TypeError``).

    ## Info

    Returned by ``step`` (and by ``reset``, with risks 0, ``risk_violation`` False and the reward
    terms 0); $M$ is the number of objects of ``base_scenario``:

    | key | value |
    | --- | --- |
    | ``risk``, ``cost`` | $R_{k+1|k} = \sum_i R_i$ (float) |
    | ``risk_terms`` | $R_i$ of each object, in scenario order, ``(M,)`` float64 (0 for an absent one) |
    | ``episode_risk`` | sum of ``risk`` since ``reset`` (float): Safety-Gymnasium's per-episode cost |
    | ``risk_violation`` | ``risk > scenario.risk_tolerance`` (bool) |
    | ``collision`` | some object within $r_e + r_{o,i}$ (bool) |
    | ``distance`` | smallest centre distance ego-object after the step [m] (float) |
    | ``closest_object`` | index of the object at that distance (int) |
    | ``path_error`` | $e$ at the closest path point, ``(4,)`` float64 |
    | ``lambda`` | arc length of the closest path point [m] (float) |
    | ``ego``, ``object`` | true ``(c1, c2, theta, v)`` of the ego, of the first object, ``(4,)`` float64 |
    | ``objects`` | the same of every object, ``(M, 4)`` float64 (zeros for an absent one) |
    | ``present`` | whether each object crosses in this episode, ``(M,)`` bool |
    | ``rewards`` | the named reward terms (dict of float) |
    | ``is_success`` | goal reached without a collision (bool) |

    ## Example

    >>> import gymnasium as gym
    >>> import risk_env
    >>> env = gym.make("RiskCrossing-v0", uncertainty="medium", risk_tolerance=500.0, v_ref=3.0)
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(np.array([3.0, 0.0], dtype=np.float32))
    >>> obs.shape, info["risk"] >= 0.0
    ((16,), True)
    >>> gym.make("RiskCrossing-v0", scene="two_crossing").reset(seed=0)[0].shape
    (22,)

    ## Version History

    - v0: initial version; ``randomize``, the vectorised form (``gym.make_vec("RiskCrossing-v0",
      num_envs=...)``, :mod:`risk_env.envs.vector_env`), several objects (``scene``, ``objects``,
      ``object_slots``; the observation's object slots with presence flags) added.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 2.0}

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
        scene: str | None = None,
        object_slots: int | None = None,
        predictor: str | Predictor | None = None,
        **overrides: Any,
    ) -> None:
        base = arguments.build_scenario(
            uncertainty, risk_tolerance, scenario, scene, overrides, _ENV_ARGUMENTS
        )
        self.base_scenario: Scenario = base
        """The scenario given at construction (the episodes' own with ``randomize=False``)."""
        self.scenario: Scenario = base
        r"""The current episode's scenario; its ``risk_tolerance`` is the env's $\epsilon$."""
        self.object_slots: int = arguments.slot_count(object_slots, base)
        """K: the observation's object slots."""
        self.randomize = checks.flag("randomize", randomize)
        self.variations: Variations = arguments.check_variations(variations, self.randomize)
        self.object_motion = checks.text("object_motion", object_motion, OBJECT_MOTIONS)
        self.reward_risk_weight = arguments.check_weight(reward_risk_weight)
        self.predictor: Predictor | None = arguments.check_predictor(predictor, base)
        """The objects' predictor (None: the paper's, built in; see Arguments)."""
        self.estimators: tuple[RiskEstimator, ...] = make_estimators(risk_estimator, base)
        """One risk estimator per object of ``base_scenario``: their terms sum to ``info["risk"]``."""
        self.estimator: RiskEstimator = self.estimators[0]
        """The first object's estimator (its ``name`` is the env's risk estimator)."""
        self.render_mode = arguments.check_render_mode(render_mode, self.metadata["render_modes"])
        self.renderer = checks.text("renderer", renderer, RENDERERS)
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / base.dt}

        self.action_space = spaces.Box(*observation.action_bounds(base.ego), dtype=np.float32)
        self.observation_space = spaces.Box(*observation.bounds(self.object_slots), dtype=np.float32)
        self._uncertainties = base.uncertainties
        self._radii = base.collision_distances
        self._start(base)
        self._objects: list[tuple[float, ...]] | None = (
            None  # each: c1, c2, theta, v, omega; None: no reset yet
        )
        self._view = EnvView(self.renderer, render_mode, self.metadata["render_fps"], self.estimator.name)

    @property
    def epsilon(self) -> float:
        r"""The risk tolerance $\epsilon$ (``scenario.risk_tolerance``)."""
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
    def observation_slices(self) -> dict[str, slice]:
        """Names of the observation's parts (:func:`risk_env.observation.slices`)."""
        return observation.slices(self.object_slots)

    @property
    def object_measurement(self) -> np.ndarray:
        """The first object's measurement ``(c1, c2, theta, v, omega)``, as :func:`predict` takes it."""
        self._require_reset()
        return np.array(self._objects[0], dtype=float)

    @property
    def object_measurements(self) -> np.ndarray:
        """Every present object's current measurement ``(m, 5)``, in scenario order."""
        self._require_reset()
        return np.array(self._objects, dtype=float)

    @property
    def plan(self) -> np.ndarray | None:
        """The planned ego positions set by :meth:`set_plan` ``(M, 2)`` [m], or None."""
        return self._view.plan

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
        self._start(self.scenario)
        self._view.set_plan(None)
        obs, info, _ = self._observe([0.0] * len(self._objects), 0.0, stepped=False)
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        """Apply ``action = (v [m/s], omega [rad/s])`` for one sample time (see the class docstring)."""
        self._require_reset()
        if self._ended is not None:
            raise gym.error.ResetNeeded(f"the episode has ended ({self._ended}); call env.reset() to step on")
        s = self.scenario
        v, omega = applied_action(action, s.ego)
        # 1.-3. the ego moves (dynamics.step's unicycle); each object moves from its one-step
        # belief B_i, made from its measurement before the move; the risk terms R_i of the ego's
        # new state against each B_i. Python floats throughout: numpy's per-call cost would dominate.
        count = len(self._objects)
        uniforms = self.np_random.random(3 * count).tolist() if self.object_motion == "sampled" else None
        self._ego_pose, self._objects, terms = advance_one(
            s,
            self.estimators,
            self._uncertainties,
            self._ego_pose,
            (v, omega),
            self._objects,
            uniforms,
            self.np_random,
            self.predictor,
        )
        risk = total(terms)
        self._ego_input = (v, omega)
        self._last_risk = risk
        self._episode_risk += risk
        self._steps += 1
        # 4. reward terms, episode end, observation, info
        obs, info, goal = self._observe(terms, risk, stepped=True)
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
        if self.render_mode is not None:
            self._require_reset()
        pose, speed, objects = self._ego_pose, self._ego_input[0], self._objects
        return self._view.frame(self.scenario, pose, speed, objects, self._steps, self._last_risk)

    def close(self) -> None:
        self._view.close()

    def set_plan(self, xy: np.ndarray | None) -> None:
        """Show a planned ego trajectory ``(M, 2)`` positions [m] in renders; None clears it.

        For benchmarks and demos only (agents read observations and never call this); the plan
        has no effect on the dynamics and is cleared by ``reset``.
        """
        self._view.set_plan(xy)

    # ---------------------------------------------------------------- internals
    def _start(self, s: Scenario) -> None:
        """The state at the start of an episode of ``s``."""
        self._ego_pose: tuple[float, float, float] = s.ego.start.as_tuple()  # unwrapped
        self._ego_input: tuple[float, float] = s.ego.initial_input
        self._objects = [(*o.start.as_tuple(), o.speed, o.turn_rate) for o in s.objects]
        self._present: np.ndarray = np.arange(len(self._radii)) < len(s.objects)
        self._steps = 0
        self._ended: str | None = None  # why the episode ended, until reset
        self._last_risk = 0.0
        self._episode_risk = 0.0

    def _require_reset(self) -> None:
        if self._objects is None:
            raise gym.error.ResetNeeded("call env.reset() before env.step() or env.render()")

    def _observe(
        self, terms: list[float], risk: float, stepped: bool
    ) -> tuple[np.ndarray, dict[str, Any], bool]:
        """Observation, info and whether the goal is reached (:func:`~risk_env.envs.transition.view`);
        the reward terms are 0 at reset."""
        weight = self.reward_risk_weight if stepped else None
        state = (self._ego_pose, self._ego_input, self._objects, self._present)
        return view(
            self.scenario, self._radii, self.object_slots, state, terms, risk, self._episode_risk, weight
        )


_ENV_ARGUMENTS: tuple[str, ...] = tuple(
    name
    for name in inspect.signature(RiskCrossingEnv.__init__).parameters
    if name not in ("self", "overrides")
)
