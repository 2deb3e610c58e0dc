"""Collision risk R = E[I_C(q_e, q_o) s(v_e, v_o)] and its estimators (paper Sec. VI-C).

One interface, :class:`RiskEstimator`, serves the env, the agents, the tests and the benchmarks:

- :class:`MonteCarloRisk`: the paper's eq. (16), the mean of I_C s over J draws;
- :class:`ExactRisk`: positions and speed are independent, I_C uses positions only and s speeds
  only, so R = P(||q_e - q_o|| <= r_e + r_o) E[s], the disc probability by fixed-node
  Gauss-Legendre quadrature, E[s] in closed form (for the injury severity by fixed 1-D
  quadrature). Smooth and deterministic;
- :class:`WorstCaseRisk`: max over the truncation box and speed interval of I_C s (eq. 17), the
  exact box form (point-to-box distance) or the paper's L-point grid (``grid=True``).

The ego state is ``(c1 [m], c2 [m], theta [rad], v [m/s])`` on a last axis of 4 (numpy) or a
CasADi vector of 4; the object's distribution is a :class:`~risk_env.prediction.Belief`. numpy
forms broadcast the ego's batch shape against the belief's.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from typing import Any

import casadi as ca
import numpy as np

from risk_env.exact_kernel import disc_probability_batch, disc_probability_scalar
from risk_env.ops import CASADI, MATH, NUMPY, Ops
from risk_env.prediction import Belief
from risk_env.quadrature import (
    EDGE,
    GAUSS_W,
    GAUSS_X,
    GEOMETRY_FLOOR,
    SIGMA_BREAKS,
    SOLVER_SHORTFALL,
    SOLVER_SIGMA_BREAKS,
    SOLVER_SUPPORT,
    SUPPORT,
)
from risk_env.quadrature import GAUSS_NODES as GAUSS_NODES
from risk_env.scenario import Scenario
from risk_env.severity import Severity, make_severity

_BELIEF_FIELDS = tuple(f.name for f in dataclasses.fields(Belief))
EgoFloats = tuple[float, float, float, float]
"""One ego state ``(c1 [m], c2 [m], theta [rad], v [m/s])`` as Python floats."""
ESTIMATOR_NAMES: tuple[str, ...] = ("exact", "monte_carlo", "worst_case", "grid")

_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
MIN_WIDTH = 1e-3
"""Smallest width [m] of the Monte Carlo estimator's smoothed indicator (draws of a point mass)."""


def _ego_parts(ego: Any) -> tuple[Any, Any, Any, Any]:
    if isinstance(ego, np.ndarray):
        if ego.shape[-1:] != (4,):
            raise ValueError(f"ego state must have a last axis of 4 (c1, c2, theta, v), got {ego.shape}")
        return ego[..., 0], ego[..., 1], ego[..., 2], ego[..., 3]
    return ego[0], ego[1], ego[2], ego[3]


def _shape(a: Any) -> tuple[int, ...]:
    """``np.shape(a)``, without its array conversion for floats and arrays."""
    if isinstance(a, float):
        return ()
    return a.shape if isinstance(a, np.ndarray) else np.shape(a)


def _floor(a: Any) -> Any:
    """``a`` raised to :data:`GEOMETRY_FLOOR`; Python floats stay floats."""
    return max(a, GEOMETRY_FLOOR) if isinstance(a, (float, int)) else np.maximum(a, GEOMETRY_FLOOR)


def disc_probability(
    dx: Any,
    dy: Any,
    radius: float,
    belief: Belief,
    ops: Ops = NUMPY,
    gate: bool = True,
    sigma_breaks: tuple[float, ...] = SIGMA_BREAKS,
    support: float = SUPPORT,
) -> Any:
    """P(||d - z|| <= radius) for z ~ truncated N(0, diag(sigma_x^2, sigma_y^2)) on the box
    ``[-half_x, half_x] x [-half_y, half_y]``; ``(dx, dy)`` = ego centre minus object mean [m].
    ``sigma_breaks`` and ``support``: the rule (:mod:`risk_env.quadrature`; default the env's).

    One axis (the inner) is integrated in closed form with Phi, the other (the outer) by
    Gauss-Legendre quadrature in the disc angle t (x = dx + r sin t, which removes the
    square-root ends of the chord). The outer axis is the one along which the ego is least
    offset, so near the object the disc boundary runs along it and the sharp crossing of the
    boundary falls to the closed form. The outer integral is split where the box edges cut the
    disc and at fixed multiples of the outer standard deviation.

    Derivatives (the CasADi face) are those of the integral, not of where the rule puts its
    nodes: the segment edges are held constant (:meth:`~risk_env.ops.Ops.stop_derivative`),
    which is exact for the integral because the integrand is continuous across every interior
    edge (Leibniz's rule: the terms of a moving edge cancel between its two segments), and the
    motion of the outer range's two ends, where the integrand jumps to 0, enters through two
    extra nodes at the held ends whose weights are the ends' motion: 0 in value, Leibniz's term
    to second order in derivatives. Each node's term is then a product of a function of dx and
    one of dy, cheap to differentiate: the exact SMPC's Hessian of the Lagrangian takes 54 % fewer
    instructions than through the edges (asin, acos, the sorting network), its Jacobian 46 %
    fewer (with the same rule; the SMPC's shorter rule saves 14 % more). The gradient
    is the quadrature of P's gradient, which differs from the derivative of the rule's value by
    the rule's sensitivity to where its edges lie: on the plans of six closed loops (the risky
    steps, 264 of them) by 2e-5 of the gradient in the median and 1.2 % at most, and it is the
    closer of the two to P's own gradient (median 8e-6 against 2.5e-5). A converged plan meets
    the constraint's value exactly and is stationary to that accuracy.
    The Hessian is the quadrature of P's Hessian less one rank-one term per kink where a
    chord's end crosses the box's inner edge inside the range (the kink's motion: its slope
    jump times the outer product of its angle's gradient), which only shapes the solver's
    steps: with that term (8 more nodes, 20 % more instructions) the 18 closed loops of
    ``benchmarks.timing`` took the same iterations. ``tests/test_risk.py`` holds both against
    finite differences of an adaptive quadrature.
    """
    r = radius
    sx = ops.maximum(belief.sigma_x, GEOMETRY_FLOOR)
    sy = ops.maximum(belief.sigma_y, GEOMETRY_FLOOR)
    hx = ops.maximum(belief.half_x, GEOMETRY_FLOOR)
    hy = ops.maximum(belief.half_y, GEOMETRY_FLOOR)
    swap = ops.abs(dx) > ops.abs(dy)
    dx, dy = ops.select(swap, dy, dx), ops.select(swap, dx, dy)  # one derivative path each
    sx, sy = ops.where(swap, sy, sx), ops.where(swap, sx, sy)
    hx, hy = ops.where(swap, hy, hx), ops.where(swap, hx, hy)
    ex = ops.expand

    # Angles where the outer coordinate meets a box edge or a multiple of its sigma ...
    at_x = ops.stack([-hx, hx, *(k * sx for k in sigma_breaks)])
    at_x = ops.clip(at_x, -support * ex(sx), support * ex(sx))
    t_x = ops.asin(ops.clip((at_x - ex(dx)) / r, -EDGE, EDGE))
    t_lo = ops.part(t_x, slice(0, 1))
    t_hi = ops.maximum(ops.part(t_x, slice(1, 2)), t_lo)
    # ... and where the chord's ends cross the inner box edges: r cos t = |hy -+ dy|.
    a = ops.acos(ops.clip(ops.stack([ops.abs(hy - dy), ops.abs(hy + dy)]) / r, 0.0, EDGE))
    inner = ops.sort(ops.clip(ops.stack_vectors([ops.part(t_x, slice(2, None)), a, -a]), t_lo, t_hi))
    edges = ops.stop_derivative(ops.stack_vectors([t_lo, inner, t_hi]))
    lo, hi = ops.part(edges, slice(0, -1)), ops.part(edges, slice(1, None))
    k, segments = len(GAUSS_X), len(sigma_breaks) + 5
    half = ops.repeat(0.5 * (hi - lo), k)
    t = ops.repeat(0.5 * (hi + lo), k) + half * ops.const(np.tile(GAUSS_X, segments))
    w = half * ops.const(np.tile(GAUSS_W, segments))
    # The range's ends move (held edges do not): a node at each held end, halfway along its
    # motion, weighted by that motion (-lo, +hi), adds 0 in value and Leibniz's term in derivatives.
    held_lo, held_hi = ops.part(edges, slice(0, 1)), ops.part(edges, slice(-1, None))
    move_lo, move_hi = t_lo - held_lo, t_hi - held_hi
    t = ops.stack_vectors([t, held_lo + 0.5 * move_lo, held_hi + 0.5 * move_hi])
    w = ops.stack_vectors([w, -move_lo, move_hi])

    half_chord = r * ops.cos(t)
    x = ex(dx) + r * ops.sin(t)
    top, bottom = ex(dy) + half_chord, ex(dy) - half_chord
    ky = 1.0 / (_SQRT2 * sy)
    zx = ops.erf(hx / (_SQRT2 * sx))
    zy = ops.erf(hy * ky)
    # Complementary form: the exact mass of the outer range times the full inner mass, minus what
    # the chord misses; exact wherever the chord spans the inner box. Twice the missed inner mass:
    # above the chord 2 (Phi(hy) - Phi(top)), below it 2 (Phi(bottom) - Phi(-hy)), at most 2 zy
    # (a chord that misses the box).
    above = ops.maximum(ex(zy) - ops.erf(top * ex(ky)), 0.0)
    below = ops.maximum(ex(zy) + ops.erf(bottom * ex(ky)), 0.0)
    missed_twice = ops.minimum(above + below, 2.0 * ex(zy))
    u = x * ex(1.0 / (_SQRT2 * sx))
    missed = ops.sum(w * half_chord * ops.exp(-u * u) * missed_twice) * (0.5 * _INV_SQRT_2PI) / sx
    s_lo, s_hi = ops.sin(ops.part(t_lo, 0)), ops.sin(ops.part(t_hi, 0))
    x_lo, x_hi = dx + r * s_lo, dx + r * s_hi
    mass = ops.norm_cdf(x_hi / sx) - ops.norm_cdf(x_lo / sx)
    p = ops.clip((mass * zy - missed) / (zx * zy), 0.0, 1.0)
    if not gate:  # the caller passes only states whose disc meets the box
        return p
    # Exactly 0 when the disc misses the box (the complementary form leaves ~1e-7 there).
    return ops.where(signed_box_distance(dx, dy, hx, hy, ops) < r, p, 0.0 * p)


def signed_box_distance(dx: Any, dy: Any, half_x: Any, half_y: Any, ops: Ops = NUMPY) -> Any:
    """Signed distance [m] from the point ``(dx, dy)`` to the box ``[-hx, hx] x [-hy, hy]``:
    Euclidean outside, minus the distance to the nearest edge inside."""
    qx = ops.abs(dx) - half_x
    qy = ops.abs(dy) - half_y
    ox, oy = ops.maximum(qx, 0.0), ops.maximum(qy, 0.0)
    outside = ops.sqrt(ox * ox + oy * oy + 1e-12) - 1e-6
    return outside + ops.minimum(ops.maximum(qx, qy), 0.0)


class RiskEstimator(ABC):
    """R_{n|k} for ego states against the object's belief at the same prediction step.

    ``risk`` is the numpy form (batched by broadcasting); ``casadi_risk`` the symbolic one;
    ``casadi_margin(ego, belief, epsilon)`` is >= 0 exactly when R <= epsilon, scaled for a solver.
    """

    name: str
    smooth: bool = True
    """Whether the CasADi form has useful gradients everywhere (False: piecewise smooth)."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.severity: Severity = make_severity(scenario)
        self.radius = scenario.collision_distance

    @abstractmethod
    def _risk(self, ego: Any, belief: Belief, ops: Ops, **kwargs: Any) -> Any: ...

    def risk(self, ego: np.ndarray, belief: Belief, rng: np.random.Generator | None = None) -> np.ndarray:
        """R for ``ego (..., 4)`` states: shape ``(...)`` broadcast with the belief's fields."""
        return np.asarray(self._risk(np.asarray(ego, dtype=float), belief, NUMPY))

    def risk_one(self, ego: EgoFloats, belief: Belief, rng: np.random.Generator | None = None) -> float:
        """R for one ego state ``(c1, c2, theta, v)`` of floats against a belief of floats, as a
        float: :meth:`risk`'s value, without its array round trip where the estimator has a
        scalar form (the single env's step)."""
        return float(self.risk(np.array(ego, dtype=float), belief, rng=rng))

    def casadi_risk(self, ego: ca.SX, belief: Belief, **kwargs: Any) -> ca.SX:
        """The symbolic R for a CasADi ego vector of 4 and a belief of CasADi scalars."""
        return self._risk(ego, belief, CASADI, **kwargs)

    def casadi_margin(self, ego: ca.SX, belief: Belief, epsilon: float | ca.SX, **kwargs: Any) -> ca.SX:
        """``(epsilon - R) / scale``: >= 0 when the constraint R <= epsilon holds."""
        return (epsilon - self.casadi_risk(ego, belief, **kwargs)) / self.severity.scale

    def __repr__(self) -> str:
        return f"{type(self).__name__}(severity={self.severity.name!r})"


SCALAR_LOOP_MAX = 8
"""Up to this many states near the box, :class:`ExactRisk` integrates them one by one with the
scalar kernel (~20 us each) rather than the batch kernel, whose fixed cost (~150 us) exceeds a few
scalar calls."""


class ExactRisk(RiskEstimator):
    """R = P(disc) E[s]: deterministic and smooth in the ego state.

    :meth:`casadi_margin`, what the SMPC constrains, integrates P with the solver's rule: the
    env's cut at +-5 sigma of the outer axis (:data:`~risk_env.quadrature.SOLVER_SUPPORT`; 40
    nodes, not 48, the others the same), whose P falls below the env's by at most
    :data:`~risk_env.quadrature.SOLVER_SHORTFALL` (5.7e-7), which it adds back wherever the disc
    meets the box: never below the env's R, above it by at most 5.7e-7 E[s] (0.02 J for the
    paper's severities). :meth:`casadi_risk` is the env's R itself.
    """

    name = "exact"

    def _risk(self, ego, belief, ops, gate=True, **kwargs):
        x, y, th, v = _ego_parts(ego)
        p = disc_probability(x - belief.x, y - belief.y, self.radius, belief, ops, gate)
        return p * self.severity.expected(v, th, belief, ops)

    def solver_risk(self, ego: ca.SX, belief: Belief) -> ca.SX:
        """The symbolic R the SMPC constrains: P by the solver's rule plus its shortfall (where
        the disc meets the box), times E[s]; at or above the env's R."""
        x, y, th, v = _ego_parts(ego)
        dx, dy = x - belief.x, y - belief.y
        p = disc_probability(dx, dy, self.radius, belief, CASADI, False, SOLVER_SIGMA_BREAKS, SOLVER_SUPPORT)
        hx = ca.fmax(belief.half_x, GEOMETRY_FLOOR)
        hy = ca.fmax(belief.half_y, GEOMETRY_FLOOR)
        near = signed_box_distance(dx, dy, hx, hy, CASADI) < self.radius
        p = near * ca.fmin(p + SOLVER_SHORTFALL, 1.0)
        return p * self.severity.expected(v, th, belief, CASADI)

    def casadi_margin(self, ego, belief, epsilon, **kwargs):
        """``(epsilon - R) / scale`` with the solver's R (:meth:`solver_risk`): conservative."""
        return (epsilon - self.solver_risk(ego, belief)) / self.severity.scale

    def risk(self, ego, belief, rng=None):
        """As :meth:`RiskEstimator.risk`; states whose disc misses the truncation box get exactly
        0 without quadrature (the same value the full formula gives), the rest are integrated by
        the numpy kernels of :mod:`risk_env.exact_kernel` (equal to the generic form to rounding)."""
        ego = np.asarray(ego, dtype=float)
        fields = vars(belief)
        if ego.shape == (4,) and all(isinstance(fields[f], (float, int)) for f in _BELIEF_FIELDS):
            return np.asarray(self.risk_one(ego.tolist(), belief))
        x, y, th, v = _ego_parts(ego)
        dx, dy = x - belief.x, y - belief.y
        sx, sy, hx, hy = (_floor(fields[f]) for f in ("sigma_x", "sigma_y", "half_x", "half_y"))
        near = signed_box_distance(dx, dy, hx, hy) < self.radius
        shapes = {near.shape, *(_shape(fields[f]) for f in _BELIEF_FIELDS)} - {()}
        shape = shapes.pop() if len(shapes) == 1 else np.broadcast_shapes(*shapes)
        if near.shape != shape:
            near = np.broadcast_to(near, shape)
        near = near.reshape(-1)
        m = np.count_nonzero(near)
        out = np.zeros(shape)
        if m == 0:
            return out
        index = None if m == near.size else np.flatnonzero(near)
        if m <= SCALAR_LOOP_MAX:  # the batch kernel's fixed cost exceeds a few scalar calls
            flat = out.reshape(-1)
            states = np.broadcast_to(ego, shape + (4,)).reshape(-1, 4)
            scalars = {f: a for f, a in fields.items() if not _shape(a)}
            arrays = {f: np.broadcast_to(a, shape).reshape(-1) for f, a in fields.items() if _shape(a)}
            for i in range(out.size) if index is None else index.tolist():
                one = Belief(**scalars, **{f: float(a[i]) for f, a in arrays.items()})
                flat[i] = self.risk_one(states[i].tolist(), one)
            return out

        def pick(a: Any) -> Any:
            """``a`` at the near states, flattened; scalars stay scalars."""
            a = np.asarray(a, dtype=float)
            if a.ndim == 0:
                return a
            if a.shape != shape:
                a = np.broadcast_to(a, shape)
            a = a.reshape(-1)
            return a if index is None else a[index]

        p = disc_probability_batch(
            np.broadcast_to(pick(dx), (m,)),
            np.broadcast_to(pick(dy), (m,)),
            self.radius,
            *(pick(a) for a in (sx, sy, hx, hy)),
        )
        near_belief = Belief(**{f: pick(fields[f]) for f in _BELIEF_FIELDS})
        p *= self.severity.expected(pick(v), pick(th), near_belief, NUMPY)
        if index is None:
            return p.reshape(shape)
        out.reshape(-1)[index] = p
        return out

    def risk_one(self, ego, belief, rng=None):
        """As :meth:`RiskEstimator.risk_one`: the gate and E[s] on the MATH face, P by the scalar
        kernel (exactly 0 without integrating when the disc misses the truncation box)."""
        x, y, th, v = ego
        dx, dy = x - belief.x, y - belief.y
        hx = max(belief.half_x, GEOMETRY_FLOOR)
        hy = max(belief.half_y, GEOMETRY_FLOOR)
        if not signed_box_distance(dx, dy, hx, hy, MATH) < self.radius:
            return 0.0
        sx = max(belief.sigma_x, GEOMETRY_FLOOR)
        sy = max(belief.sigma_y, GEOMETRY_FLOOR)
        p = disc_probability_scalar(
            float(dx), float(dy), self.radius, float(sx), float(sy), float(hx), float(hy)
        )
        return p * float(self.severity.expected(v, th, belief, MATH))


class MonteCarloRisk(RiskEstimator):
    """The paper's eq. (16): ``(1/J) sum_j I_C(q_e, q_o,j) s(v_e, v_o,j)``.

    numpy (:meth:`risk`): J draws from the passed-in generator per call, the hard indicator and the
    severity as they are: the paper's estimator.

    CasADi (:meth:`casadi_risk`, for the SMPC): the draws are parameters ``samples (J, 3)`` of
    (c1, c2, v), and the sum is smoothed so that a gradient-based solver can follow it:

    - the indicator ``1[d_j <= r]`` becomes the logistic ``1 / (1 + exp((d_j - r) / h))`` with a
      width ``h = bandwidth * sqrt(sigma_x sigma_y)`` proportional to the spread of the draws (a
      kernel bandwidth; floored at :data:`MIN_WIDTH`), or a fixed ``smoothing`` [m] if given.
      Relative to the spacing of the draws near the disc edge, which scales with sigma too, the
      width is then the same at every step and uncertainty: wide enough that the sum is a smooth
      ramp rather than a staircase of single draws (a fixed 0.05 m is below the spacing of 500
      draws with sigma = 6 m), narrow enough that its bias is small;
    - the severity's kinks (the paper's ``|m_e v_e^2 - m_o v_o^2|`` has one per draw, exactly
      where the SMPC likes to put the ego speed) are rounded by
      :meth:`~risk_env.severity.Severity.smooth_value`, which lies above s by at most
      ``w = severity_smoothing * scale`` (50 J for the paper's severity).

    Both tend to the paper's estimator as ``bandwidth``, ``severity_smoothing`` -> 0. The bias
    against the hard estimator on the same draws is bounded by :meth:`smoothing_bound`:
    ``(1/J) sum_j exp(-|d_j - r| / h) s_j + w`` (the logistic differs from the step by less than
    ``exp(-|d - r| / h)``). In expectation over the draws it is O(h^2): about
    ``(pi^2 / 6) h^2 f_d'(r)`` in probability, ``f_d`` the density of the ego-object distance, i.e.
    ``~0.5 bandwidth^2`` times the local probability density scale, 1e-3 for the default 0.05.
    """

    name = "monte_carlo"

    def __init__(
        self,
        scenario: Scenario,
        samples: int | None = None,
        bandwidth: float = 0.05,
        smoothing: float | None = None,
        severity_smoothing: float = 0.05,
    ) -> None:
        super().__init__(scenario)
        self.samples = scenario.mc_samples if samples is None else int(samples)
        if self.samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        if not bandwidth > 0:
            raise ValueError(f"bandwidth must be > 0 (a fraction of the draws' spread), got {bandwidth}")
        if smoothing is not None and not smoothing > 0:
            raise ValueError(f"smoothing must be > 0 [m], got {smoothing}")
        if not severity_smoothing >= 0:
            raise ValueError(f"severity_smoothing must be >= 0, got {severity_smoothing}")
        self.bandwidth = float(bandwidth)
        self.smoothing = None if smoothing is None else float(smoothing)
        self.severity_smoothing = float(severity_smoothing)

    @property
    def severity_width(self) -> float:
        """w [units of the severity]: the smoothed severity lies in [s, s + w]."""
        return self.severity_smoothing * self.severity.scale

    def width(self, belief: Belief, ops: Ops = NUMPY) -> Any:
        """h [m], the logistic's width at this belief: ``bandwidth * sqrt(sigma_x sigma_y)`` (at
        least :data:`MIN_WIDTH`), or the fixed ``smoothing``."""
        if self.smoothing is not None:
            return self.smoothing
        spread = ops.sqrt(ops.maximum(belief.sigma_x, 0.0) * ops.maximum(belief.sigma_y, 0.0))
        return ops.maximum(self.bandwidth * spread, MIN_WIDTH)

    def risk(self, ego, belief, rng=None, draws: np.ndarray | None = None):
        """As :meth:`RiskEstimator.risk`; needs ``rng`` (a numpy Generator) or ``draws (J, ..., 3)``."""
        ego = np.asarray(ego, dtype=float)
        if draws is None:
            if rng is None:
                raise ValueError("the Monte Carlo estimator needs rng=np.random.Generator (or draws)")
            draws = belief.sample(rng, self.samples)
        x, y, th, v = _ego_parts(ego)
        draws = self._pad(draws, x)
        hit = np.hypot(x - draws[..., 0], y - draws[..., 1]) <= self.radius
        s = self.severity.value(v, th, draws[..., 2], belief.theta, NUMPY)
        return np.mean(hit * s, axis=0)

    def smoothing_bound(self, ego: np.ndarray, belief: Belief, draws: np.ndarray) -> np.ndarray:
        """Bound on ``|smoothed - hard|`` on the same ``draws (J, ..., 3)`` [units of the severity]:
        ``(1/J) sum_j exp(-|d_j - r| / h) s_j + w``."""
        ego = np.asarray(ego, dtype=float)
        x, y, th, v = _ego_parts(ego)
        draws = self._pad(draws, x)
        d = np.hypot(x - draws[..., 0], y - draws[..., 1])
        s = self.severity.value(v, th, draws[..., 2], belief.theta, NUMPY)
        near = np.exp(-np.abs(d - self.radius) / self.width(belief))
        return np.mean(near * (s + self.severity_width), axis=0) + self.severity_width

    @staticmethod
    def _pad(draws: np.ndarray, x: np.ndarray) -> np.ndarray:
        # draws (J, *belief_batch, 3): pad so J stays first when the ego batch has more axes
        extra = max(np.ndim(x) - (draws.ndim - 2), 0)
        return draws.reshape(draws.shape[:1] + (1,) * extra + draws.shape[1:])

    @staticmethod
    def distances(ego: Any, samples: Any) -> Any:
        """CasADi: distances ``(J,)`` [m] from the ego centre to the draws ``samples (J, 3)``."""
        x, y, _, _ = _ego_parts(ego)
        dx = x - samples[:, 0]
        dy = y - samples[:, 1]
        return ca.sqrt(dx * dx + dy * dy + 1e-12)

    def _risk(self, ego, belief, ops, samples=None, **kwargs):
        if samples is None:
            raise ValueError("the CasADi Monte Carlo risk needs samples=(J, 3) draws")
        _, _, th, v = _ego_parts(ego)
        dist = self.distances(ego, samples)
        # logistic written with tanh: no overflow (and no NaN gradient) for far draws
        inverse = 0.5 / self.width(belief, CASADI)  # once, not per draw
        hit = 0.5 * (1.0 - ca.tanh((dist - self.radius) * inverse))
        s = self.severity.smooth_value(v, th, samples[:, 2], belief.theta, ops, self.severity_width)
        return ca.sum1(hit * s) / samples.shape[0]


class WorstCaseRisk(RiskEstimator):
    """``max I_C s`` over the truncation box and speed interval (paper eq. 17).

    Exact box form (default): [signed distance to the box <= r] times the worst severity over the
    speed interval. ``grid=True``: the paper's under-approximation on L points per interval
    (L = ``scenario.grid_points``), evaluated through the nearest grid point per axis, which
    equals the brute-force maximum over the L^3 grid.
    """

    smooth = False

    def __init__(self, scenario: Scenario, grid: bool = False, grid_points: int | None = None) -> None:
        super().__init__(scenario)
        self.grid = grid
        self.grid_points = scenario.grid_points if grid_points is None else int(grid_points)
        if self.grid_points < 2:
            raise ValueError(f"grid_points must be >= 2, got {grid_points}")
        self.name = "grid" if grid else "worst_case"

    def _snap(self, d: Any, half: Any, ops: Ops) -> Any:
        """The grid point of ``[-half, half]`` (L points) nearest to ``d``."""
        h = ops.maximum(half, GEOMETRY_FLOOR)
        spacing = 2.0 * h / (self.grid_points - 1)
        return -h + spacing * ops.floor((ops.clip(d, -h, h) + h) / spacing + 0.5)

    def distance(self, ego: Any, belief: Belief, ops: Ops = NUMPY) -> Any:
        """Distance [m] from the ego centre to the nearest possible object centre (signed for
        the box: negative inside)."""
        x, y, _, _ = _ego_parts(ego)
        dx, dy = x - belief.x, y - belief.y
        if not self.grid:
            return signed_box_distance(dx, dy, belief.half_x, belief.half_y, ops)
        ex = dx - self._snap(dx, belief.half_x, ops)
        ey = dy - self._snap(dy, belief.half_y, ops)
        return ops.sqrt(ex * ex + ey * ey + 1e-12) - 1e-6

    def worst_severity(self, ego: Any, belief: Belief, ops: Ops = NUMPY) -> Any:
        """max of s over the speed interval (or its L grid points)."""
        _, _, th, v = _ego_parts(ego)
        lo, hi = belief.v_lo, belief.v_hi
        near0 = ops.clip(0.0 * v, lo, hi)
        if self.grid:
            mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
            near0 = mid + self._snap(near0 - mid, half, ops)
        return self.severity.worst(v, th, lo, hi, near0, belief.theta, ops)

    def _risk(self, ego, belief, ops, **kwargs):
        hit = self.distance(ego, belief, ops) <= self.radius
        s = self.worst_severity(ego, belief, ops)
        return ops.where(hit, s, 0.0 * s)

    def risk_one(self, ego, belief, rng=None):
        """As :meth:`RiskEstimator.risk_one`: the same formulas on the MATH face."""
        return float(self._risk(ego, belief, MATH))

    def casadi_margin(self, ego, belief, epsilon, **kwargs):
        """``max(distance - r [m], (epsilon - s_worst) / scale) >= 0``: keep the ego disc off
        every possible object position, unless even the worst severity is tolerable."""
        clearance = self.distance(ego, belief, CASADI) - self.radius
        slack = (epsilon - self.worst_severity(ego, belief, CASADI)) / self.severity.scale
        return ca.fmax(clearance, slack)


def make_estimator(name: str, scenario: Scenario, **kwargs: Any) -> RiskEstimator:
    """The estimator called ``name`` (one of :data:`ESTIMATOR_NAMES`) for ``scenario``."""
    if name == "exact":
        return ExactRisk(scenario, **kwargs)
    if name == "monte_carlo":
        return MonteCarloRisk(scenario, **kwargs)
    if name == "worst_case":
        return WorstCaseRisk(scenario, **kwargs)
    if name == "grid":
        return WorstCaseRisk(scenario, grid=True, **kwargs)
    raise ValueError(f"unknown risk estimator {name!r}; expected one of {ESTIMATOR_NAMES}")
