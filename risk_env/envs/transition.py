"""The env's transition as pure functions, shared by :class:`~risk_env.envs.env.RiskCrossingEnv` (Python
floats, the :data:`~risk_env.models.ops.MATH` face) and
:class:`~risk_env.envs.vector_env.RiskCrossingVectorEnv`
(arrays ``(B,)``, the :data:`~risk_env.models.ops.NUMPY` face).

Each function is written once against an :class:`~risk_env.models.ops.Ops` face, so one env and a batch
evaluate the very same formulas. Objects come as a sequence of measurements, one per object of
the scenario, in its order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from risk_env import checks, observation
from risk_env.models.dynamics import turn_limit, unicycle_step
from risk_env.models.ops import MATH, NUMPY, Ops
from risk_env.models.path import AnyPath, path_error, project
from risk_env.prediction.belief import Belief, predict_step
from risk_env.prediction.mixture import Mixture
from risk_env.prediction.predictors import Predictor
from risk_env.risk.estimators import RiskEstimator
from risk_env.risk.mixture_risk import mixture_risk
from risk_env.scenario.scenario import Scenario

Measurement = tuple[Any, Any, Any, Any, Any]
"""An object's ``(c1 [m], c2 [m], theta [rad], v [m/s], omega [rad/s])``, floats or arrays."""


def move_object(
    belief: Belief, measurement: Measurement, uniforms: Any | None, ops: Ops = NUMPY
) -> Measurement:
    """The object's next measurement given its one-step belief.

    ``uniforms=None``: the paper's motion, B's mean (its unicycle with constant inputs).
    ``uniforms`` on [0, 1), ``(..., 3)`` (numpy) or 3 floats: its next (c1, c2, v) is the draw
    :meth:`Belief.from_uniforms` makes, its heading advances with the mean model and its turn
    rate stays.
    """
    omega = measurement[4]
    if uniforms is None:
        return belief.x, belief.y, belief.theta, measurement[3], omega
    draw = belief.from_uniforms(uniforms, ops)
    return ops.part(draw, 0), ops.part(draw, 1), belief.theta, ops.part(draw, 2), omega


def advance_one(
    scenario: Scenario,
    estimators: Sequence[RiskEstimator],
    uncertainties: Sequence[Any],
    pose: Any,
    action: tuple[float, float],
    measurements: Sequence[Any],
    uniforms: list[float] | None,
    rng: np.random.Generator,
    predictor: Predictor | None = None,
) -> tuple[tuple[float, float, float], list[Measurement], list[float]]:
    r"""Steps 1-3 of the transition for one state, in Python floats (the MATH face).

    The ego at ``pose`` $(c_1, c_2, \theta)$ moves under ``action`` $= (v, \omega)$; each object $i$
    moves from its one-step belief $B_i$, made from its measurement ``measurements[i]`` with
    ``uncertainties[i]`` (``uniforms``: 3 floats on [0, 1) per object, in order, for the sampled
    motion; None for the paper's); its risk term $R_i$ is the ego's new state against $B_i$ by
    ``estimators[i]`` (Monte Carlo draws from ``rng``, object by object). Returns the new pose, the
    new measurements and the terms $R_i$ (their sum is the step's risk,
    :mod:`risk_env.risk.total_risk`). With a ``predictor`` (None: the paper's, built in) $B_i$ is its
    mixture's step 1 (:func:`_advance_by`).
    """
    v, omega = action
    x, y, theta = unicycle_step(pose[0], pose[1], pose[2], v, omega, scenario.dt, MATH)
    ego = (x, y, theta, v)
    if predictor is not None:
        pairs = [
            _advance_by(predictor, scenario, estimators[i], uncertainties[i], ego, m, uniforms, i, rng)
            for i, m in enumerate(measurements)
        ]
        return (x, y, theta), [moved for moved, _ in pairs], [risk for _, risk in pairs]
    if len(measurements) == 1:  # the paper's scene: no loop (a step costs ~15 us)
        moved, risk = _advance_object(
            scenario, estimators[0], uncertainties[0], ego, measurements[0], uniforms, rng
        )
        return (x, y, theta), [moved], [risk]
    pairs = [
        _advance_object(
            scenario, estimators[i], uncertainties[i], ego, m, uniforms and uniforms[3 * i : 3 * i + 3], rng
        )
        for i, m in enumerate(measurements)
    ]
    return (x, y, theta), [moved for moved, _ in pairs], [risk for _, risk in pairs]


def _advance_object(
    scenario: Scenario,
    estimator: RiskEstimator,
    uncertainty: Any,
    ego: tuple[float, float, float, float],
    measurement: Any,
    uniforms: list[float] | None,
    rng: np.random.Generator,
) -> tuple[Measurement, float]:
    """One object's step of :func:`advance_one`: its next measurement and its risk term $R_i$."""
    belief = predict_step(scenario, measurement, 1, MATH, uncertainty)
    return move_object(belief, measurement, uniforms, MATH), estimator.risk_one(ego, belief, rng=rng)


def _advance_by(
    predictor: Predictor,
    scenario: Scenario,
    estimator: RiskEstimator,
    uncertainty: Any,
    ego: tuple[float, float, float, float],
    measurement: Any,
    uniforms: list[float] | None,
    index: int,
    rng: np.random.Generator,
) -> tuple[Measurement, float]:
    r"""Object ``index``'s step with a ``predictor``: $B_i$ is its mixture at $n = 1$, the risk term
    $R_i$ the mixture's (:func:`~risk_env.risk.mixture_risk.mixture_risk`: $\sum_m w_m R_m$, or the
    worst case over the modes). The paper's motion stays the object's own unicycle; the sampled
    one draws from the mixture: the mode by one more uniform from ``rng`` when there are several,
    then $(c_1, c_2, v)$ from it with the object's 3 uniforms."""
    modes = predictor.predict(measurement, 1).at(1)
    risk = float(mixture_risk(estimator, ego, modes, rng=rng))
    if uniforms is None:
        return move_object(
            predict_step(scenario, measurement, 1, MATH, uncertainty), measurement, None, MATH
        ), risk
    belief = modes[0][1]
    if len(modes) > 1:
        belief = Mixture.pick(modes, float(rng.random()))
    return move_object(belief, measurement, uniforms[3 * index : 3 * index + 3], MATH), risk


class Observed(NamedTuple):
    """What the env reports about a state; floats for one env, arrays ``(B, ...)`` for a batch."""

    obs: np.ndarray
    """Observation ``(..., 10 + 6 K)`` float32 (layout: :mod:`risk_env.observation`)."""
    path_error: np.ndarray
    """e ``(..., 4)`` float64 at the closest path point [m, m, rad, m/s]."""
    lam: Any
    """Arc length of the closest path point [m]."""
    distance: Any
    """Smallest centre distance ego-object over the present objects [m]."""
    closest: Any
    """Index of the object at that distance (int)."""
    collision: Any
    """Whether some present object $i$ is within $r_e + r_{o,i}$."""
    goal: Any
    r"""$\lambda \ge \lambda_g$ (``lam``)."""
    error_norm: Any
    r"""$\|e\|$ [mixed units, as the paper's ``e_acc``]."""


def observe(
    path: AnyPath,
    v_ref: float,
    collision_distances: Sequence[float],
    ego_pose: tuple[Any, Any, Any],
    ego_input: tuple[Any, Any],
    measurements: Sequence[Measurement],
    slots: int,
    present: Sequence[Any] | None = None,
    ops: Ops = NUMPY,
) -> Observed:
    r"""Observation and the state's path error, progress, distance, collision and goal flags.

    ``measurements``: one per object ($M \le$ ``slots``), filling slots $0, \dots, M-1$; ``present``: None
    (every object present) or one flag per object, a bool or ``(B,)`` bools (an absent object's
    slot is all zeros, and it neither collides nor counts for the distance).
    """
    x, y, theta = ego_pose
    v, omega = ego_input
    lam = project(path, x, y, ops)
    error = path_error(path, x, y, theta, v, lam, v_ref, ops)
    wrap = ops.wrap_angle
    values = [x, y, wrap(theta), v, omega, lam, *error]
    e1, e2, e3, e4 = error
    error_norm = ops.sqrt(e1 * e1 + e2 * e2 + e3 * e3 + e4 * e4)
    if ops is MATH and present is None:  # one state, every object present: the float fast path
        distance, closest, collision = math.inf, 0, False
        for i, (ox, oy, otheta, ov, oomega) in enumerate(measurements):
            values += (1.0, ox, oy, wrap(otheta), ov, oomega)
            d = math.hypot(x - ox, y - oy)
            collision = collision or d <= collision_distances[i]
            if d < distance:
                distance, closest = d, i
        values += [0.0] * (observation.SLOT_SIZE * (slots - len(measurements)))
        packed = np.array(values)
        return Observed(
            packed.astype(np.float32),
            packed[observation.PATH_ERROR],
            lam,
            distance,
            closest,
            collision,
            lam >= path.lambda_goal,
            error_norm,
        )
    distances, collisions = [], []
    for i, (ox, oy, otheta, ov, oomega) in enumerate(measurements):
        flag = True if present is None else present[i]
        d = ops.hypot(x - ox, y - oy)
        if flag is True:
            values += [1.0, ox, oy, wrap(otheta), ov, oomega]
        elif flag is False:
            values += [0.0] * observation.SLOT_SIZE
            d = math.inf
        else:  # per copy
            zero = 0.0 * ox
            values.append(flag.astype(float))
            values += [ops.where(flag, a, zero) for a in (ox, oy, wrap(otheta), ov, oomega)]
            d = ops.where(flag, d, math.inf)
        distances.append(d)
        collisions.append(d <= collision_distances[i])
    values += [0.0] * (observation.SLOT_SIZE * (slots - len(measurements)))
    packed = ops.pack(values)
    if len(distances) == 1:
        closest = 0 if ops is MATH else np.zeros(np.shape(distances[0]), dtype=np.int64)
        distance, collision = distances[0], collisions[0]
    elif ops is MATH:
        closest = min(range(len(distances)), key=distances.__getitem__)
        distance, collision = distances[closest], any(collisions)
    else:
        table = np.array(distances)
        closest = np.argmin(table, axis=0)
        distance = np.take_along_axis(table, closest[None], axis=0)[0]
        collision = np.any(collisions, axis=0)
    return Observed(
        obs=packed.astype(np.float32),
        path_error=packed[..., observation.PATH_ERROR],
        lam=lam,
        distance=distance,
        closest=closest,
        collision=collision,
        goal=lam >= path.lambda_goal,
        error_norm=error_norm,
    )


def reward_terms(error_norm: Any, risk: Any, risk_weight: float) -> dict[str, Any]:
    r"""The named reward terms of a step: $-\|e_{k+1}\|$ and $-w R_{k+1|k}$."""
    return {"path_error": 0.0 - error_norm, "risk": 0.0 - risk_weight * risk}


def view(
    scenario: Scenario,
    radii: Sequence[float],
    slots: int,
    state: tuple[Sequence[float], Sequence[float], list[tuple[float, ...]], np.ndarray],
    terms: Sequence[float],
    risk: float,
    episode_risk: float,
    risk_weight: float | None,
) -> tuple[np.ndarray, dict[str, Any], bool]:
    r"""The single env's observation ``(10 + 6 K,)``, ``info`` (see
    :class:`~risk_env.envs.env.RiskCrossingEnv`) and whether the goal is reached, from its
    ``state``: the ego's pose $(c_1, c_2, \theta)$ and last input $(v, \omega)$, the episode's objects'
    measurements $(c_1, c_2, \theta, v, \omega)$ and which of the base scenario's $M$ objects are
    ``present``; ``radii``: $r_e + r_{o,i}$ of the $M$ objects; ``terms``: each episode object's $R_i$;
    ``risk_weight``: the reward's $w$ (None at reset: the reward terms are 0)."""
    pose, ego_input, objects, present = state
    seen = observe(scenario.path, scenario.ego.v_ref, radii, pose, ego_input, objects, slots, None, MATH)
    if risk_weight is None:
        rewards = {"path_error": 0.0, "risk": 0.0}
    else:
        rewards = reward_terms(seen.error_norm, risk, risk_weight)
    if len(objects) == len(radii):
        states = np.array(objects)[:, :4]
    else:  # objects of the base scenario not in this episode: zeros
        states = np.zeros((len(radii), 4))
        states[: len(objects)] = [o[:4] for o in objects]
        terms = [*terms, *[0.0] * (len(radii) - len(objects))]
    collision, goal = seen.collision, seen.goal
    info = {
        "risk": risk,
        "cost": risk,
        "risk_terms": np.array(terms),
        "episode_risk": episode_risk,
        "risk_violation": risk > scenario.risk_tolerance,
        "collision": collision,
        "distance": seen.distance,
        "closest_object": seen.closest,
        "path_error": seen.path_error,
        "lambda": seen.lam,
        "ego": np.array((pose[0], pose[1], pose[2], ego_input[0])),
        "object": states[0].copy(),
        "objects": states,
        "present": present.copy(),
        "rewards": rewards,
        "is_success": goal and not collision,
    }
    return seen.obs, info, goal


def applied_action(action: Any, ego: Any) -> tuple[float, float]:
    """The single env's ``action`` checked (:func:`risk_env.checks.ego_action`) as the ``(v [m/s],
    omega [rad/s])`` the ego applies: ``omega`` within ``ego``'s curvature limit
    (:func:`risk_env.models.dynamics.turn_limit`; a car turns only while it moves)."""
    v, omega = checks.ego_action(action, ego)
    return v, float(turn_limit(ego.curvature_max, omega, v))
