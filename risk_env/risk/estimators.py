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
CasADi vector of 4; the object's distribution is a :class:`~risk_env.prediction.belief.Belief`. numpy
forms broadcast the ego's batch shape against the belief's.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from typing import Any

import casadi as ca
import numpy as np

from risk_env.models.ops import CASADI, MATH, NUMPY, Ops
from risk_env.prediction.belief import Belief
from risk_env.risk.disc import disc_probability, signed_box_distance
from risk_env.risk.exact_kernel import disc_probability_batch, disc_probability_scalar
from risk_env.risk.quadrature import GAUSS_NODES as GAUSS_NODES
from risk_env.risk.quadrature import (
    GEOMETRY_FLOOR,
    SOLVER_SHORTFALL,
    SOLVER_SIGMA_BREAKS,
    SOLVER_SUPPORT,
)
from risk_env.risk.severity import Severity, make_severity
from risk_env.scenario.scenario import Scenario

_BELIEF_FIELDS = tuple(f.name for f in dataclasses.fields(Belief))
EgoFloats = tuple[float, float, float, float]
"""One ego state ``(c1 [m], c2 [m], theta [rad], v [m/s])`` as Python floats."""
ESTIMATOR_NAMES: tuple[str, ...] = ("exact", "monte_carlo", "worst_case", "grid")

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
    env's cut at +-5 sigma of the outer axis (:data:`~risk_env.risk.quadrature.SOLVER_SUPPORT`; 40
    nodes, not 48, the others the same), whose P falls below the env's by at most
    :data:`~risk_env.risk.quadrature.SOLVER_SHORTFALL` (5.7e-7), which it adds back wherever the disc
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
        the numpy kernels of :mod:`risk_env.risk.exact_kernel` (equal to the generic form to rounding)."""
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
      :meth:`~risk_env.risk.severity.Severity.smooth_value`, which lies above s by at most
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
