r"""The PPO baseline: what the policy sees, how its actions become inputs, and loading a trained one.

A policy trained by ``python -m benchmarks.train_ppo`` acts through two fixed maps, used alike in
training (as Gymnasium vector wrappers) and by :class:`PPOAgent`:

- :func:`features`: the observation -> 14 scaled features in the ego's frame (path
  error, own input, the object's relative position, heading and velocity, distance, progress);
  :class:`FeatureSpec` adds the episode's :class:`Context` (the risk tolerance $\epsilon$ on a log
  scale and the uncertainty's growth per step) and, optionally, the object's prediction over the
  horizon (means and truncation boxes in the ego's frame); with ``slots`` $K > 1$ it shows every
  object slot (:func:`slot_features`, each present object's prediction, absent slots zeroed);
- :func:`to_inputs`: the policy's action in $[-1, 1]^2$ -> the change of ``(v, omega)`` within one
  step's rate limits (``accel_max`` $dt$, ``omega_rate_max`` $dt$), clipped to the input limits, so a
  learned policy obeys the same rate limits as the MPCs.

Needs the ``rl`` extra (``pip install "riskcrossing[rl]"``: torch CPU and stable-baselines3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import as_batch
from agents.ppo.metadata import build, read_metadata
from agents.ppo.network import LIBM, PolicyNet, load_model
from risk_env import checks
from risk_env import observation as layout
from risk_env.models.dynamics import unicycle_step
from risk_env.scenario.parts import Uncertainty
from risk_env.scenario.scenario import Scenario

FEATURES = 14
"""Length of :func:`features`."""
_SCALE = np.array([5.0, 5.0, 1.0, 4.0, 4.0, 0.8, 20.0, 20.0, 1.0, 1.0, 8.0, 8.0, 20.0, 100.0])
"""Divisors of the raw features [m, m, rad, m/s, m/s, rad/s, m, m, -, -, m/s, m/s, m, m]."""
SHIPPED = Path(__file__).resolve().parents[1] / "models"
"""The trained policies that ship with the package: ``ppo_penalty``, ``ppo_lagrangian`` and
``ppo_lagrangian_two_crossing`` (two object slots, trained with ``--scene two_crossing``)."""
METADATA_SUFFIX = ".json"
"""A model ``policy.zip`` ships with ``policy.json``: the limits it acts within and how it was trained."""


def shipped_model(variant: str) -> Path:
    """The shipped policy of a training variant: ``"penalty"``, ``"lagrangian"`` or
    ``"lagrangian_two_crossing"``."""
    path = SHIPPED / f"ppo_{variant}.zip"
    if not path.is_file():
        known = sorted(p.stem.removeprefix("ppo_") for p in SHIPPED.glob("ppo_*.zip"))
        raise ValueError(f"no shipped PPO policy {variant!r}; shipped: {known}")
    return path


def features(obs: np.ndarray) -> np.ndarray:
    """Scaled features ``(B, 14)`` float32 of observations ``(B, 10 + 6 K)`` (or ``(14,)`` of one),
    of the first present object (the policies are trained on one); ``ValueError`` for an
    observation without any."""
    o = np.asarray(obs, dtype=float)
    single = o.ndim == 1
    o = np.atleast_2d(o)
    x, y, theta = o[:, layout.EGO_POSE].T
    v, omega = o[:, layout.EGO_INPUT].T
    ox, oy, otheta, ov = first_object(o)
    c, s = LIBM.cos(theta), LIBM.sin(theta)
    dx, dy = ox - x, oy - y
    rel_heading = otheta - theta
    rel_c, rel_s = LIBM.cos(rel_heading), LIBM.sin(rel_heading)
    # the object's velocity relative to the ego's, in the ego's frame
    vx = ov * rel_c - v
    vy = ov * rel_s
    raw = np.stack(
        (
            *(o[:, layout.PATH_ERROR].T),
            v,
            omega,
            c * dx + s * dy,
            -s * dx + c * dy,
            rel_c,
            rel_s,
            vx,
            vy,
            LIBM.hypot(dx, dy),
            o[:, layout.PROGRESS],
        ),
        axis=-1,
    )
    out = (raw / _SCALE).astype(np.float32)
    return out[0] if single else out


EPSILON_UNIT = 500.0
r"""$\epsilon$'s feature is $\log(1 + \epsilon / \epsilon_u) / \log 6$, $\epsilon_u$ = ``EPSILON_UNIT``
[$\epsilon$ in the training severity's unit, J by default]: 0 at $\epsilon = 0$, 1 at the paper's
largest tolerance 2500 J."""
CONTEXT_SIZE = 6
r"""Columns of a context array: $\epsilon$'s feature, the c1 $\sigma$ growth [m/step], the box growth
(c1, c2) [m/step], the box half widths at the measurement (c1, c2) [m]."""


@dataclass(frozen=True)
class Context:
    r"""What a tolerance-conditioned policy is told about its episode: $\epsilon$ and the uncertainty."""

    epsilon: float
    """The risk tolerance [the severity's unit]."""
    uncertainty: Uncertainty
    """The object's prediction model (the Table I level)."""

    def array(self) -> np.ndarray:
        """The context as one row ``(CONTEXT_SIZE,)``."""
        u = self.uncertainty
        eps = math.log1p(max(self.epsilon, 0.0) / EPSILON_UNIT) / math.log1p(5.0)
        return np.array([eps, u.sigma_growth[0], *u.box_growth[:2], *u.box_half_width0], dtype=float)


@dataclass(frozen=True)
class FeatureSpec:
    r"""Which features a policy sees: the 14 of :func:`features`, the context's 3 ($\epsilon$, $\sigma$
    growth / 1.5 m, box growth / 3 m) and with ``prediction`` the object's predicted mean (ego
    frame, / 20 m) and its truncation box's half extents along the ego's axes (/ 10 m) at each
    of ``steps``.

    With ``slots`` $K > 1$ the policy sees every slot instead of the first present object: the
    ego's 7 of :func:`slot_features`, 8 per slot (flag and the object's 7), the context's 3, and
    with ``prediction`` $4 \times$ ``len(steps)`` per slot; an absent slot's entries are all 0.
    """

    prediction: bool = False
    dt: float = 0.5
    """Step length [s] of the prediction."""
    steps: tuple[int, ...] = (2, 4, 6)
    """Prediction steps n whose mean and box the policy sees."""
    slots: int = 1
    """K, the observation's object slots the policy is trained for (1: the first present object)."""

    def __post_init__(self) -> None:
        checks.flag("prediction", self.prediction)
        object.__setattr__(self, "dt", checks.positive("dt", self.dt))
        if not isinstance(self.steps, tuple) or not self.steps:
            raise TypeError(f"steps must be a non-empty tuple of integers, got {checks.describe(self.steps)}")
        object.__setattr__(self, "steps", tuple(checks.integer("steps", n, minimum=1) for n in self.steps))
        object.__setattr__(self, "slots", checks.integer("slots", self.slots, minimum=1))

    @property
    def size(self) -> int:
        """Length of the feature vector: ``14 + 3 (+ 4 len(steps))`` with one slot, ``7 + 8 K + 3
        (+ 4 len(steps) K)`` with K > 1."""
        per_slot = 4 * len(self.steps) if self.prediction else 0
        if self.slots == 1:
            return FEATURES + 3 + per_slot
        return EGO_FEATURES + SLOT_FEATURES * self.slots + 3 + per_slot * self.slots

    def __call__(self, obs: np.ndarray, context: np.ndarray) -> np.ndarray:
        """Features ``(B, size)`` float32 of observations ``(B, 10 + 6 K)`` and contexts
        ``(B, CONTEXT_SIZE)`` (or ``(size,)`` of one observation and one context row)."""
        o = np.asarray(obs, dtype=float)
        single = o.ndim == 1
        o = np.atleast_2d(o)
        ctx = np.broadcast_to(np.asarray(context, dtype=float), (len(o), CONTEXT_SIZE))
        scaled = (ctx[:, :3] / np.array([1.0, 1.5, 3.0])).astype(np.float32)
        if self.slots == 1:
            parts = [features(o), scaled]
            if self.prediction:
                table = slot_table(o)
                first = table[np.arange(len(o)), np.argmax(table[:, :, 0] == 1.0, axis=1)]
                parts.append(self._prediction(o, ctx, first[:, 1:6]))
        else:
            found = layout.slot_count(o.shape[1])
            if found != self.slots:
                raise ValueError(
                    f"the policy was trained on {self.slots} object slots; the observation has {found}"
                )
            parts = [slot_features(o), scaled]
            if self.prediction:
                table = slot_table(o)
                for i in range(self.slots):
                    there = (table[:, i, 0] == 1.0)[:, None]
                    parts.append(np.where(there, self._prediction(o, ctx, table[:, i, 1:6]), 0.0))
        out = np.concatenate(parts, axis=1).astype(np.float32)
        return out[0] if single else out

    def _prediction(self, o: np.ndarray, ctx: np.ndarray, measured: np.ndarray) -> np.ndarray:
        """``(B, 4 len(steps))``: per step n, the predicted mean of the object measured ``(B, 5)``
        (c1, c2, theta, v, omega) in the ego's frame and the box's half extents along the ego's
        axes (the c1/c2 box rotated into the ego's frame)."""
        x, y, theta = o[:, layout.EGO_POSE].T
        c, s = LIBM.cos(theta), LIBM.sin(theta)
        ox, oy, oth, ov, ow = measured.T
        out, n_prev = [], 0
        for n in self.steps:
            for _ in range(n - n_prev):
                ox, oy, oth = unicycle_step(ox, oy, oth, ov, ow, self.dt, LIBM)
            n_prev = n
            hx, hy = ctx[:, 4] + n * ctx[:, 2], ctx[:, 5] + n * ctx[:, 3]
            dx, dy = ox - x, oy - y
            out += [(c * dx + s * dy) / 20.0, (-s * dx + c * dy) / 20.0]
            out += [(np.abs(c) * hx + np.abs(s) * hy) / 10.0, (np.abs(s) * hx + np.abs(c) * hy) / 10.0]
        return np.stack(out, axis=1).astype(np.float32)


def slot_table(obs: np.ndarray) -> np.ndarray:
    """The object slots ``(B, K, 6)`` (flag, c1, c2, theta, v, omega) of observations ``(B, 10 + 6 K)``."""
    return obs[:, layout.EGO_SIZE :].reshape(len(obs), layout.slot_count(obs.shape[1]), layout.SLOT_SIZE)


EGO_FEATURES = 7
"""Ego columns of :func:`slot_features`: path error (4), v, omega, progress."""
SLOT_FEATURES = 8
"""Columns per slot of :func:`slot_features`: flag, relative position (2), relative heading's
cos and sin, relative velocity (2), distance."""


def slot_features(obs: np.ndarray) -> np.ndarray:
    """Scaled features ``(B, 7 + 8 K)`` float32 of observations ``(B, 10 + 6 K)``: the ego's 7
    (path error, v, omega, progress; scaled as in :func:`features`), then per slot its flag and
    the object's 7 of :func:`features` (ego frame), all 0 for an absent slot."""
    o = np.atleast_2d(np.asarray(obs, dtype=float))
    x, y, theta = o[:, layout.EGO_POSE].T
    v, omega = o[:, layout.EGO_INPUT].T
    c, s = LIBM.cos(theta), LIBM.sin(theta)
    ego = np.stack((*(o[:, layout.PATH_ERROR].T), v, omega, o[:, layout.PROGRESS]), axis=-1)
    parts = [ego / _SCALE[[0, 1, 2, 3, 4, 5, 13]]]
    for row in np.moveaxis(slot_table(o), 1, 0):  # (B, 6) per slot
        flag, ox, oy, otheta, ov = row[:, :5].T
        dx, dy, rel = ox - x, oy - y, otheta - theta
        rel_c, rel_s = LIBM.cos(rel), LIBM.sin(rel)
        raw = np.stack(
            (
                c * dx + s * dy,
                -s * dx + c * dy,
                rel_c,
                rel_s,
                ov * rel_c - v,
                ov * rel_s,
                LIBM.hypot(dx, dy),
            ),
            axis=-1,
        )
        there = (flag == 1.0)[:, None]
        parts += [flag[:, None], np.where(there, raw / _SCALE[6:13], 0.0)]
    return np.concatenate(parts, axis=1).astype(np.float32)


def first_object(obs: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(c1, c2, theta, v)`` ``(B,)`` each of the first present object of observations ``(B, 10 + 6 K)``."""
    table = slot_table(obs)
    present = table[:, :, 0] == 1.0
    empty = ~present.any(axis=1)
    if empty.any():
        raise ValueError(f"observation(s) {np.flatnonzero(empty).tolist()} hold no object: all slots absent")
    first = table[np.arange(len(obs)), np.argmax(present, axis=1)]
    return first[:, 1], first[:, 2], first[:, 3], first[:, 4]


@dataclass(frozen=True)
class InputLimits:
    """The input and rate limits an action is mapped into (from a Scenario's ego)."""

    v_min: float
    v_max: float
    omega_max: float
    dv_max: float
    """Largest speed change per step [m/s] (accel_max dt)."""
    domega_max: float
    """Largest turn-rate change per step [rad/s] (``omega_rate_max`` $dt$)."""

    @classmethod
    def of(cls, scenario: Scenario, forward_only: bool = False) -> InputLimits:
        r"""The limits of ``scenario``'s ego; ``forward_only``: no reversing ($v \ge 0$)."""
        e = scenario.ego
        v_min = max(e.v_min, 0.0) if forward_only else e.v_min
        return cls(v_min, e.v_max, e.omega_max, e.accel_max * scenario.dt, e.omega_rate_max * scenario.dt)


def to_inputs(action: np.ndarray, last_input: np.ndarray, limits: InputLimits) -> np.ndarray:
    """Inputs ``(B, 2)`` (v [m/s], omega [rad/s]) from policy actions ``(B, 2)`` in [-1, 1] (clipped)
    and the last applied inputs ``(B, 2)``."""
    a = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
    last = np.asarray(last_input, dtype=float)
    v = np.clip(last[..., 0] + a[..., 0] * limits.dv_max, limits.v_min, limits.v_max)
    omega = np.clip(last[..., 1] + a[..., 1] * limits.domega_max, -limits.omega_max, limits.omega_max)
    return np.stack((v, omega), axis=-1)


class PPOAgent:
    """A trained stable-baselines3 PPO policy with the MPC agents' ``predict`` API.

    ``predict`` takes RiskCrossing-v0 observations ``(10 + 6 K,)`` or ``(B, 10 + 6 K)`` (a
    one-slot policy: any K, it sees the first present object, :func:`features`; a policy trained
    with K > 1 slots, ``spec.slots``: exactly that K) and returns inputs in physical units ``(2,)``
    or ``(B, 2)``, within the scenario's input and rate limits.
    """

    def __init__(
        self,
        model: Any,
        limits: InputLimits,
        metadata: dict[str, Any] | None = None,
        spec: FeatureSpec | None = None,
        context: Context | None = None,
    ) -> None:
        self.model = model
        """The SB3 PPO model (torch): samples the non-deterministic actions."""
        self.policy = PolicyNet.from_sb3(model.policy)
        """The deterministic action in float64 from the model's weights, the same on every CPU."""
        self.limits = limits
        self.spec = spec
        """The conditioned features the policy sees; None: the 14 of :func:`features` alone."""
        self.context = context
        r"""The episode's $\epsilon$ and uncertainty told to a conditioned policy (``spec`` not None)."""
        self.metadata: dict[str, Any] = dict(metadata or {})
        """How the policy was trained (the training arguments, wall time, steps/s), as saved."""
        self.last_solve = None
        """Always None: a policy has no solve to report (the rollout records its predict time)."""

    @classmethod
    def load(cls, path: str | Path, scenario: Scenario | None = None) -> PPOAgent:
        r"""Load ``path`` (an SB3 ``.zip``) and its ``.json`` metadata beside it.

        The input limits are the saved ones, or ``scenario``'s when given (a different car). A
        tolerance-conditioned policy (metadata ``feature_spec``) is told ``scenario``'s $\epsilon$ and
        uncertainty (without a scenario: $\epsilon = 0$ and the medium level); its severity must be
        the one it was trained with, since $\epsilon$ is read in that unit.
        """
        if scenario is not None and not isinstance(scenario, Scenario):
            raise TypeError(
                "scenario must be a risk_env Scenario (e.g. Scenario.preset('medium') or"
                f" env.unwrapped.scenario) or None, got {checks.describe(scenario)}"
            )
        path = Path(path)
        zip_path = path if path.suffix == ".zip" else path.with_suffix(".zip")
        if not zip_path.is_file():
            raise FileNotFoundError(
                f"no PPO model at {zip_path}; train one with python -m benchmarks.train_ppo"
            )
        meta_path = zip_path.with_suffix(METADATA_SUFFIX)
        metadata = read_metadata(meta_path)
        if scenario is not None:
            limits = InputLimits.of(scenario, bool(metadata.get("args", {}).get("forward_only", False)))
        elif "limits" in metadata:
            limits = build(meta_path, "limits", InputLimits, metadata["limits"])
        else:
            raise ValueError(f"{meta_path} is missing: pass scenario= to set the input limits")
        fields = metadata.get("feature_spec")
        spec = None if fields is None else build(meta_path, "feature_spec", FeatureSpec, fields)
        expected = FEATURES if spec is None else spec.size
        if (trained_on := metadata.get("features", FEATURES)) != expected:
            raise ValueError(f"{zip_path} was trained on {trained_on} features; this version has {expected}")
        context = None
        if spec is not None:
            trained = metadata.get("args", {}).get("severity", "paper")
            if scenario is None:
                context = Context(0.0, Uncertainty.preset("medium"))
            elif scenario.severity != trained:
                raise ValueError(
                    f"{zip_path} reads epsilon in the {trained!r} severity's unit; the scenario's"
                    f" severity is {scenario.severity!r}"
                )
            else:
                context = Context(scenario.risk_tolerance, scenario.uncertainty)
        model = load_model(zip_path)
        return cls(model, limits, metadata, spec, context)

    def reset(self) -> None:
        """Nothing to reset (the policy is memoryless); for the rollout loop's sake."""

    def predict(
        self,
        observation: np.ndarray,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, None]:
        """Inputs for ``observation (10 + 6 K,)`` or ``(B, 10 + 6 K)``; raises on a wrong shape or a NaN.
        ``deterministic``: the policy's mean action, evaluated in float64 (:class:`PolicyNet`) so
        that it is the same on every CPU; otherwise an action sampled by SB3 (torch)."""
        length = np.shape(observation)[-1] if np.ndim(observation) else 0
        size = layout.size(layout.slot_count(length)) if length > layout.SIZE else layout.SIZE
        obs, single = as_batch(observation, size)
        if not np.all(np.isfinite(obs)):
            raise ValueError(f"observation has non-finite entries: {observation}")
        if self.spec is None or self.context is None:
            seen = features(obs)
        else:
            seen = self.spec(obs, self.context.array())
        if deterministic:
            action = np.clip(self.policy(seen), -1.0, 1.0)  # as SB3 clips to the action space
        else:
            action, _ = self.model.predict(seen, deterministic=False)
        inputs = to_inputs(action, obs[:, layout.EGO_INPUT], self.limits)
        return (inputs[0] if single else inputs), None
