r"""The stress benchmark's scenes: a seeded family of random crossings, the object's true motion in
each, and the witness that tells an avoidable collision from an unavoidable one.

A scene (:func:`make_scenes`, reproducible from ``(seed, index)``) draws:

- the uncertainty: one of the paper's presets, or ``"enlarged"`` (:data:`ENLARGED`, 1.5 x the
  high preset's growth $Q$ and $\Delta$);
- $v_{ref}$ uniform in [1, 8] m/s and the object's motion, ``"paper"`` or ``"sampled"``;
- the ego's start near the path: arc length in [-85, -50] m, up to 2.5 m sideways, heading within
  0.4 rad of the path's; at rest, or (half the scenes) already moving at up to $\min(v_{ref}, 4)$ m/s;
- the object, one of three kinds: ``"close"`` (3.5-6 m from the ego, any heading, 0-2 m/s),
  ``"crossing"`` (timed to cross the path 2-8 s ahead, near where the ego would be then, at
  1-4 m/s) and ``"never"`` (12-25 m off the path, heading away from it or along it, 0-4 m/s).

**Infeasible steps** (:func:`infeasible_step`): for the agents whose risk row is the box clearance
(the RMPC, the exact SMPC at $\epsilon = 0$), a step is certified infeasible when no input within the
rate limits clears the truncation box at some prediction step; such a step needs a fallback level
whatever the solver does.

**Avoidable collision** (:func:`avoidable`): some open-loop manoeuvre of :func:`manoeuvres`, from
the episode's start state, keeps the ego's centre more than $r_e + r_o$ from the object's *true*
motion at every step of the episode's whole budget (``max_steps``), as the env checks it (at the
sample instants). The manoeuvres hold a target speed in $\{v_{min}, \dots, v_{max}\}$ (1 m/s apart) and a
target turn rate in $\omega_{max} \times \{0, \pm 1/8, \pm 1/4, \pm 1/2, \pm 1\}$, each reached under
the rate limits.
The object's true motion (:func:`object_truth`) does not depend on the ego: the env draws its
sampled motion from ``np_random`` and nothing else (the exact risk estimator draws nothing), so it
is replayed from the episode's seed with the env's own transition functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium.utils import seeding

from risk_env.envs.transition import move_object
from risk_env.models.dynamics import unicycle_step
from risk_env.models.ops import NUMPY
from risk_env.models.path import point
from risk_env.prediction.belief import predict
from risk_env.risk.estimators import signed_box_distance
from risk_env.scenario.scenario import Scenario, Uncertainty

LEVELS: tuple[str, ...] = ("low", "medium", "high", "enlarged")
KINDS: tuple[str, ...] = ("close", "crossing", "never")
MOTIONS: tuple[str, ...] = ("paper", "sampled")
ENLARGED = Uncertainty(sigma_growth=(2.25, 2.25, 2.25), box_growth=(4.5, 4.5, 4.5))
"""1.5 x the high preset's growth per prediction step (Q = 1.5 I, Delta = 3 per side)."""
TURN_FRACTIONS = (0.0, 0.125, -0.125, 0.25, -0.25, 0.5, -0.5, 1.0, -1.0)
r"""Target turn rates of the witness manoeuvres as fractions of $\omega_{max}$ (0, $\pm$0.1, ...,
$\pm$0.8 rad/s)."""


@dataclass(frozen=True)
class Scene:
    """One stress scene: scenario overrides, the object's kind and motion, the episode seed."""

    index: int
    uncertainty: str
    kind: str
    motion: str
    overrides: tuple[tuple[str, Any], ...]
    seed: int

    def scenario(self, risk_tolerance: float = 0.0) -> Scenario:
        r"""The scene's scenario with tolerance $\epsilon$ = ``risk_tolerance``."""
        if self.uncertainty == "enlarged":
            base = Scenario(uncertainty=ENLARGED)
        else:
            base = Scenario.preset(self.uncertainty)
        return base.replace(**dict(self.overrides), risk_tolerance=risk_tolerance)

    def env_kwargs(self, risk_tolerance: float = 0.0) -> dict[str, Any]:
        """Keyword arguments of ``gym.make("RiskCrossing-v0", ...)`` for this scene."""
        return {"scenario": self.scenario(risk_tolerance), "object_motion": self.motion}

    @property
    def label(self) -> str:
        return f"#{self.index} {self.uncertainty}/{self.kind}/{self.motion}"


def make_scenes(count: int, seed: int = 0) -> list[Scene]:
    """``count`` scenes; scene i is drawn from ``default_rng([seed, i])``, so a prefix of a larger
    run is the smaller run."""
    if count < 0:
        raise ValueError(f"count must be >= 0, got {count}")
    return [_scene(i, np.random.default_rng([seed, i]), seed) for i in range(count)]


def _scene(index: int, rng: np.random.Generator, seed: int) -> Scene:
    level = LEVELS[index % len(LEVELS)]  # every level equally often
    kind = KINDS[(index // len(LEVELS)) % len(KINDS)]
    motion = MOTIONS[rng.integers(len(MOTIONS))]
    base = Scenario()
    path = base.path
    v_ref = float(rng.uniform(1.0, 8.0))
    lam0 = float(rng.uniform(-85.0, -50.0))
    px, py, pth = point(path, lam0)
    offset = float(rng.uniform(-2.5, 2.5))
    ego = (px - math.sin(pth) * offset, py + math.cos(pth) * offset, pth + float(rng.uniform(-0.4, 0.4)))
    v0 = float(rng.uniform(0.0, min(v_ref, 4.0))) if rng.random() < 0.5 else 0.0
    if kind == "close":
        distance, bearing = float(rng.uniform(3.5, 6.0)), float(rng.uniform(-math.pi, math.pi))
        obj = (ego[0] + distance * math.cos(bearing), ego[1] + distance * math.sin(bearing))
        heading, speed = float(rng.uniform(-math.pi, math.pi)), float(rng.uniform(0.0, 2.0))
        turn = float(rng.uniform(-0.1, 0.1))
    elif kind == "crossing":
        t_cross, speed = float(rng.uniform(2.0, 8.0)), float(rng.uniform(1.0, 4.0))
        lam_c = min(lam0 + v_ref * t_cross * float(rng.uniform(0.6, 1.2)), -5.0)
        cx, cy, cth = point(path, lam_c)
        side = 1.0 if rng.random() < 0.5 else -1.0
        heading = cth + side * (0.5 * math.pi + float(rng.uniform(-0.5, 0.5)))
        travel = speed * t_cross
        obj = (cx - travel * math.cos(heading), cy - travel * math.sin(heading))
        turn = float(rng.uniform(-0.05, 0.05))
    else:
        lam_o = float(rng.uniform(lam0, -5.0))
        ox, oy, oth = point(path, lam_o)
        side = 1.0 if rng.random() < 0.5 else -1.0
        off = side * float(rng.uniform(12.0, 25.0))
        obj = (ox - math.sin(oth) * off, oy + math.cos(oth) * off)
        away = oth + side * 0.5 * math.pi
        heading = (
            away + float(rng.uniform(-0.5, 0.5))
            if rng.random() < 0.5
            else oth + float(rng.uniform(-0.2, 0.2))
        )
        speed, turn = float(rng.uniform(0.0, 4.0)), 0.0
    overrides = (
        ("v_ref", round(v_ref, 4)),
        ("ego_start", tuple(round(float(c), 4) for c in ego)),
        ("initial_input", (round(v0, 4), 0.0)),
        ("object_start", (round(obj[0], 4), round(obj[1], 4), round(float(NUMPY.wrap_angle(heading)), 4))),
        ("object_speed", round(speed, 4)),
        ("object_turn_rate", round(turn, 5)),
    )
    return Scene(index, level, kind, motion, overrides, seed=int(rng.integers(2**31)))


def object_truth(scene: Scene, steps: int | None = None) -> np.ndarray:
    """The object's true positions ``(steps+1, 2)`` [m] at k = 0..steps (default ``max_steps``):
    the env's transition replayed from the scene's seed (:mod:`risk_env.envs.transition`)."""
    sc = scene.scenario()
    steps = sc.max_steps if steps is None else steps
    rng, _ = seeding.np_random(scene.seed)
    obj = (*sc.object.start.as_tuple(), sc.object.speed, sc.object.turn_rate)
    out = [obj[:2]]
    for _ in range(steps):
        belief = predict(sc, obj, steps=1)[1]
        uniforms = rng.random(3) if scene.motion == "sampled" else None
        obj = tuple(float(a) for a in move_object(belief, obj, uniforms))
        out.append(obj[:2])
    return np.array(out)


def manoeuvres(scenario: Scenario, steps: int) -> np.ndarray:
    """The witness family's inputs ``(M, steps, 2)`` (v [m/s], omega [rad/s]) from the ego's
    initial input: each target speed and turn rate reached under the rate limits."""
    ego, dt = scenario.ego, scenario.dt
    speeds = np.arange(math.ceil(ego.v_min), math.floor(ego.v_max) + 1, 1.0)
    turns = ego.omega_max * np.array(TURN_FRACTIONS)
    v_t, w_t = (a.ravel() for a in np.meshgrid(speeds, turns, indexing="ij"))
    v, w = ego.initial_input
    out = np.empty((len(v_t), steps, 2))
    v, w = np.full(len(v_t), v), np.full(len(v_t), w)
    for k in range(steps):
        v = np.clip(v_t, v - ego.accel_max * dt, v + ego.accel_max * dt)
        w = np.clip(w_t, w - ego.omega_rate_max * dt, w + ego.omega_rate_max * dt)
        out[:, k] = np.column_stack([v, w])
    return out


def ego_positions(scenario: Scenario, inputs: np.ndarray) -> np.ndarray:
    """Ego positions ``(M, steps+1, 2)`` [m] under inputs ``(M, steps, 2)`` from the start pose."""
    m, steps, _ = inputs.shape
    x, y, th = (np.full(m, c) for c in scenario.ego.start.as_tuple())
    out = np.empty((m, steps + 1, 2))
    out[:, 0] = np.column_stack([x, y])
    for k in range(steps):
        x, y, th = unicycle_step(x, y, th, inputs[:, k, 0], inputs[:, k, 1], scenario.dt, NUMPY)
        out[:, k + 1] = np.column_stack([x, y])
    return out


def witness_clearance(scene: Scene, truth: np.ndarray | None = None) -> float:
    """The largest, over the witness manoeuvres, of the smallest centre distance to the object's
    true motion over the episode's budget, minus $r_e + r_o$ [m]: $> 0$ means a collision was avoidable."""
    sc = scene.scenario()
    truth = object_truth(scene) if truth is None else truth
    ego = ego_positions(sc, manoeuvres(sc, len(truth) - 1))
    distance = np.hypot(*(ego - truth[None]).transpose(2, 0, 1))  # (M, steps+1)
    return float(np.max(distance[:, 1:].min(axis=1)) - sc.collision_distance)


def avoidable(scene: Scene, truth: np.ndarray | None = None) -> bool:
    """Whether some witness manoeuvre keeps clear of the object's true motion (see the module)."""
    return witness_clearance(scene, truth) > 0.0


CERTIFY_GRID = 61
"""Points per input axis of :func:`infeasible_step`'s grid at n = 1."""


def infeasible_step(
    scenario: Scenario, ego_pose: np.ndarray, last_input: np.ndarray, measurement: np.ndarray, backoff: float
) -> bool:
    r"""Whether no input sequence within the bounds and rate limits keeps the ego clear of the
    object's truncation box by ``backoff`` [m] at some prediction step $n$ (the RMPC's rows, and the
    exact SMPC's at $\epsilon = 0$), so that the hard problem is infeasible. Certified at $n = 1$ on a
    grid of the first inputs, with the grid's worst position error (a Lipschitz bound) as margin;
    at every $n$ by the disc the ego can reach (the speeds under the rate limits, summed): if even
    its farthest point stays within $r_e + r_o$ of the box. ``ego_pose`` (3,), ``last_input``
    (v, omega), ``measurement`` the object's (c1, c2, theta, v, omega)."""
    ego, dt, r = scenario.ego, scenario.dt, scenario.collision_distance
    dv, dw = ego.accel_max * dt, ego.omega_rate_max * dt
    beliefs = predict(scenario, tuple(float(m) for m in measurement))[1:]
    # every n: the reachable disc
    cap = max(abs(ego.v_min), abs(ego.v_max))
    reach = np.cumsum(np.minimum(cap, abs(last_input[0]) + dv * np.arange(1, scenario.horizon + 1))) * dt
    for b, radius in zip(beliefs, reach):
        centre = signed_box_distance(ego_pose[0] - b.x, ego_pose[1] - b.y, b.half_x, b.half_y)
        if centre + radius - r < backoff:
            return True
    # n = 1: a grid of the first inputs
    v = np.linspace(max(ego.v_min, last_input[0] - dv), min(ego.v_max, last_input[0] + dv), CERTIFY_GRID)
    w = np.linspace(
        max(-ego.omega_max, last_input[1] - dw), min(ego.omega_max, last_input[1] + dw), CERTIFY_GRID
    )
    vv, ww = np.meshgrid(v, w, indexing="ij")
    x, y, _ = unicycle_step(*(np.full(vv.shape, c) for c in ego_pose[:3]), vv, ww, dt, NUMPY)
    b = beliefs[0]
    distance = signed_box_distance(x - b.x, y - b.y, b.half_x, b.half_y)
    # a position between grid points lies within this of one: the arc moves by at most dt per m/s
    # of speed and by |v| dt^2 / 2 per rad/s of turn rate
    h_v, h_w = (v[-1] - v[0]) / (CERTIFY_GRID - 1), (w[-1] - w[0]) / (CERTIFY_GRID - 1)
    slack = 0.5 * (dt * h_v + np.max(np.abs(v)) * dt * dt * h_w)
    return bool(np.max(distance) - r + slack < backoff)
