r"""The object's prediction over the horizon (paper Sec. VI-C, the truncation centred on the predicted mean).

From a measurement $(c_1, c_2, \theta, v, \omega)$ the mean follows the unicycle with the measured,
constant inputs. At step $n$ the position and the speed are independent truncated Gaussians:

- position: mean $\mu_n$, standard deviations $\Sigma_0 + n Q$ ($c_1$, $c_2$), truncated to the box
  $\mu_n \pm (h_0 + n \Delta)$ ($h_0$ = ``box_half_width0``);
- speed: mean $v$, standard deviation $\sigma_{v,0} + n Q_v$, truncated to
  $[v_{lo,0} - n \Delta_v, v_{hi,0} + n \Delta_v]$.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from risk_env.models.dynamics import unicycle_step
from risk_env.models.frame import from_frame
from risk_env.models.ops import NUMPY, Ops
from risk_env.models.truncnorm import sample as truncnorm_sample
from risk_env.models.truncnorm import transform as truncnorm_transform
from risk_env.scenario.scenario import Scenario, Uncertainty

_SPREAD_FIELDS = ("sigma_x", "sigma_y", "sigma_v", "half_x", "half_y")
r"""Fields that must be finite and $\ge 0$ (a standard deviation or a half width)."""


@dataclass(frozen=True)
class Belief:
    """The object's distribution at one or more prediction steps; fields broadcast together.

    Each field is a float or an array (numpy) or a scalar expression (CasADi). The position's
    covariance and truncation box lie in the belief's own frame, turned by :attr:`frame` from the
    world's axes: ``sigma_x`` and ``half_x`` along the frame's first axis, ``sigma_y`` and
    ``half_y`` across it (with ``frame = 0``, the default, along c1 and c2). Numbers are checked
    on construction (:meth:`check`); CasADi expressions are not.
    """

    x: Any
    """Mean c1 [m]."""
    y: Any
    """Mean c2 [m]."""
    theta: Any
    """Mean heading [rad] (deterministic)."""
    speed: Any
    """Mean speed [m/s]."""
    sigma_x: Any
    """Standard deviation along the frame's first axis [m] (c1 for ``frame = 0``)."""
    sigma_y: Any
    """Standard deviation across it [m] (c2 for ``frame = 0``)."""
    sigma_v: Any
    """Standard deviation of the speed [m/s]."""
    half_x: Any
    """Half width of the truncation box along the frame's first axis, around the mean [m]."""
    half_y: Any
    """Half width of the truncation box across it, around the mean [m]."""
    v_lo: Any
    """Lower speed truncation bound [m/s]."""
    v_hi: Any
    """Upper speed truncation bound [m/s]."""
    frame: Any = 0.0
    """Angle [rad] from the c1 axis to the frame's first axis (counter-clockwise): 0 for the
    world's axes (the paper's prediction), the heading for a heading-aligned belief."""

    SIZE = 12

    def __post_init__(self) -> None:
        self.check()

    @classmethod
    def unchecked(cls, **fields: Any) -> Belief:
        """A belief from fields that are known to be valid (taken from checked beliefs), without
        :meth:`check`: for hot paths. ``frame`` defaults to 0."""
        belief = object.__new__(cls)
        belief.__dict__.update(fields)
        if "frame" not in fields:
            belief.__dict__["frame"] = 0.0
        return belief

    def check(self) -> None:
        """Raise ``ValueError`` naming the field if a standard deviation or half width is negative,
        infinite or NaN, or the frame is not finite (numbers and numpy arrays; CasADi expressions
        pass)."""
        for name in _SPREAD_FIELDS:
            value = getattr(self, name)
            if isinstance(value, (float, int)):
                if not 0.0 <= value < math.inf:
                    raise ValueError(f"Belief.{name} must be finite and >= 0, got {value!r}")
            elif _numeric(value):
                ok = (np.asarray(value) >= 0.0) & np.isfinite(value)
                if not ok.all():
                    bad = np.asarray(value)[~ok].ravel()[0]
                    raise ValueError(f"Belief.{name} must be finite and >= 0, got {bad!r} among its entries")
        frame = self.frame
        if isinstance(frame, (float, int)):
            if not math.isfinite(frame):
                raise ValueError(f"Belief.frame must be a finite angle [rad], got {frame!r}")
        elif _numeric(frame) and not np.all(np.isfinite(frame)):
            raise ValueError("Belief.frame must be a finite angle [rad], got a non-finite entry")

    def as_array(self) -> np.ndarray:
        """The fields stacked on a last axis: ``(..., 12)``, :attr:`frame` last."""
        return np.stack(
            np.broadcast_arrays(*(np.asarray(getattr(self, f.name), float) for f in fields(self))),
            -1,
        )

    @classmethod
    def from_array(cls, a: Any) -> Belief:
        """Inverse of :meth:`as_array`; also takes a CasADi vector of 12 entries."""
        if isinstance(a, np.ndarray):
            if a.shape[-1:] != (cls.SIZE,):
                raise ValueError(f"a belief array needs a last axis of {cls.SIZE}, got shape {a.shape}")
            return cls(*(a[..., i] for i in range(cls.SIZE)))
        return cls(*(a[i] for i in range(cls.SIZE)))

    def __getitem__(self, index: Any) -> Belief:
        """Index every (numpy) field alike, e.g. ``belief[n]`` for prediction step n."""
        return Belief.unchecked(**{f.name: np.asarray(getattr(self, f.name))[index] for f in fields(self)})

    def sample(self, rng: np.random.Generator, size: int | tuple[int, ...] = ()) -> np.ndarray:
        """Draws ``(size..., batch..., 3)`` of (c1 [m], c2 [m], v [m/s]) from ``rng``: world
        coordinates, the position drawn in the belief's frame and turned into the world."""
        size = (size,) if isinstance(size, int) else tuple(size)
        if self._world_aligned():
            return truncnorm_sample(*self._marginals(), rng, size)
        shape = size + np.broadcast_shapes(*(np.shape(getattr(self, f.name)) for f in fields(self)), ())
        return self.from_uniforms(rng.random(shape + (3,)))

    def from_uniforms(self, u: Any, ops: Ops = NUMPY) -> Any:
        """The draws :meth:`sample` makes from the uniforms on [0, 1): ``u (..., batch..., 3)``
        -> ``(..., batch..., 3)`` (numpy), or 3 floats -> a list of 3 (:data:`~risk_env.models.ops.MATH`)."""
        if self._world_aligned():
            mean, sigma, lo, hi = self._marginals(ops)
            return ops.elementwise(lambda *args: truncnorm_transform(*args, ops), u, mean, sigma, lo, hi)
        zero = 0.0 * self.x
        mean = ops.stack([zero, zero, self.speed])
        sigma = ops.stack([self.sigma_x, self.sigma_y, self.sigma_v])
        lo = ops.stack([zero - self.half_x, zero - self.half_y, self.v_lo])
        hi = ops.stack([zero + self.half_x, zero + self.half_y, self.v_hi])
        local = ops.elementwise(lambda *args: truncnorm_transform(*args, ops), u, mean, sigma, lo, hi)
        along, across, v = (ops.part(local, i) for i in range(3))
        dx, dy = from_frame(along, across, self.frame, ops)
        return ops.pack([self.x + dx, self.y + dy, v]) if ops is NUMPY else [self.x + dx, self.y + dy, v]

    def _world_aligned(self) -> bool:
        """Whether the frame is the world's (0, a number or an all-zero array)."""
        frame = self.frame
        if isinstance(frame, (float, int)):
            return frame == 0.0
        return isinstance(frame, np.ndarray) and not frame.any()

    def _marginals(self, ops: Ops = NUMPY) -> tuple[Any, Any, Any, Any]:
        """Mean, standard deviation, lower and upper bound of $(c_1, c_2, v)$ of a world-aligned belief, each
        ``(batch..., 3)`` (a list of 3 with :data:`~risk_env.models.ops.MATH`)."""
        mean = ops.stack([self.x, self.y, self.speed])
        sigma = ops.stack([self.sigma_x, self.sigma_y, self.sigma_v])
        lo = ops.stack([self.x - self.half_x, self.y - self.half_y, self.v_lo])
        hi = ops.stack([self.x + self.half_x, self.y + self.half_y, self.v_hi])
        return mean, sigma, lo, hi


def _numeric(value: Any) -> bool:
    """Whether ``value`` is a numpy number or a numeric numpy array (not a CasADi expression)."""
    return isinstance(value, (np.ndarray, np.generic)) and np.asarray(value).dtype.kind in "fiub"


def predict(
    scenario: Scenario,
    measurement: Any,
    steps: int | None = None,
    ops: Ops = NUMPY,
    uncertainty: Any = None,
) -> list[Belief]:
    """Beliefs for n = 0..steps (default: the horizon N) from ``measurement``.

    ``measurement``: ``(c1 [m], c2 [m], theta [rad], v [m/s], omega [rad/s])``, a sequence of
    5 floats, arrays (batched) or CasADi scalars. ``uncertainty``: the scenario's unless given,
    any object with the fields of :class:`~risk_env.scenario.scenario.Uncertainty` (the MPC passes CasADi
    parameters, so that one built solver serves every uncertainty level).
    """
    steps = scenario.horizon if steps is None else steps
    u = scenario.uncertainty if uncertainty is None else uncertainty
    x, y, th, v, w = (measurement[i] for i in range(5))
    out = []
    for n in range(steps + 1):
        if n > 0:
            x, y, th = unicycle_step(x, y, th, v, w, scenario.dt, ops)
        out.append(_belief(u, n, x, y, th, v))
    return out


def predict_step(
    scenario: Scenario, measurement: Any, step: int = 1, ops: Ops = NUMPY, uncertainty: Any = None
) -> Belief:
    """``predict(scenario, measurement, step, ops, uncertainty)[step]`` alone: the belief at one
    prediction step (the env's B at ``step=1``), without building the others."""
    x, y, th, v, w = measurement
    for _ in range(step):
        x, y, th = unicycle_step(x, y, th, v, w, scenario.dt, ops)
    return _belief(scenario.uncertainty if uncertainty is None else uncertainty, step, x, y, th, v)


def _belief(u: Any, n: int, x: Any, y: Any, th: Any, v: Any) -> Belief:
    """The belief at prediction step ``n`` around the mean ``(x, y, th, v)``; spreads of ``u``."""
    if isinstance(u, Uncertainty):  # numbers: the spreads once per (u, n), a lean constructor
        belief = object.__new__(Belief)
        belief.__dict__.update(x=x, y=y, theta=th, speed=v, **_spreads(u, n), frame=0.0)
        return belief
    return Belief(x, y, th, v, **_spread_formulas(u, n))


def _spread_formulas(u: Any, n: int) -> dict[str, Any]:
    """Standard deviations and truncation bounds at step ``n`` (paper Sec. VI-C, Table I)."""
    return {
        "sigma_x": u.sigma0[0] + n * u.sigma_growth[0],
        "sigma_y": u.sigma0[1] + n * u.sigma_growth[1],
        "sigma_v": u.sigma0[2] + n * u.sigma_growth[2],
        "half_x": u.box_half_width0[0] + n * u.box_growth[0],
        "half_y": u.box_half_width0[1] + n * u.box_growth[1],
        "v_lo": u.velocity_bounds0[0] - n * u.box_growth[2],
        "v_hi": u.velocity_bounds0[1] + n * u.box_growth[2],
    }


@functools.lru_cache(maxsize=256)
def _spreads(u: Uncertainty, n: int) -> dict[str, float]:
    return _spread_formulas(u, n)


def predict_array(
    scenario: Scenario, measurement: np.ndarray, steps: int | None = None, uncertainty: Any = None
) -> Belief:
    """numpy convenience: one :class:`Belief` whose fields have a leading step axis ``(steps+1, ...)``."""
    beliefs = predict(scenario, np.asarray(measurement, float).T, steps, uncertainty=uncertainty)
    return Belief.from_array(np.stack([b.as_array() for b in beliefs]))
