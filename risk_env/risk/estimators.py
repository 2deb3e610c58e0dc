r"""Collision risk $R = E[I_C(q_e, q_o)\, s(v_e, v_o)]$ and its estimators (paper Sec. VI-C).

One interface, :class:`RiskEstimator`, serves the env, the agents, the tests and the benchmarks:

- :class:`MonteCarloRisk`: the paper's eq. (16), the mean of $I_C s$ over $J$ draws;
- :class:`ExactRisk`: positions and speed are independent, $I_C$ uses positions only and $s$ speeds
  only, so $R = P(\|q_e - q_o\| \le r_e + r_o)\, E[s]$, the disc probability by fixed-node
  Gauss-Legendre quadrature, $E[s]$ in closed form (for the injury severity by fixed 1-D
  quadrature). Smooth and deterministic;
- :class:`WorstCaseRisk`: max over the truncation box and speed interval of $I_C s$ (eq. 17), the
  exact box form (point-to-box distance) or the paper's $L$-point grid (``grid=True``).

:class:`ExactRisk` lives here; the interface in :mod:`risk_env.risk.estimator`, the others in
:mod:`risk_env.risk.monte_carlo` and :mod:`risk_env.risk.worst_case` (all importable from here). A belief's
covariance and box lie in its own frame (:attr:`~risk_env.prediction.belief.Belief.frame`): every
estimator turns the ego's offset into that frame (or, Monte Carlo, draws in it and turns the draws
into the world).

The ego state is ``(c1 [m], c2 [m], theta [rad], v [m/s])`` on a last axis of 4 (numpy) or a
CasADi vector of 4; the object's distribution is a :class:`~risk_env.prediction.belief.Belief`. numpy
forms broadcast the ego's batch shape against the belief's.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import casadi as ca
import numpy as np

from risk_env.models.frame import to_frame
from risk_env.models.ops import CASADI, MATH, NUMPY
from risk_env.prediction.belief import Belief
from risk_env.risk.bodies import with_bodies
from risk_env.risk.disc import disc_probability as disc_probability
from risk_env.risk.disc import signed_box_distance, support_halves
from risk_env.risk.estimator import EgoFloats as EgoFloats
from risk_env.risk.estimator import RiskEstimator, ego_parts, floor_geometry, shape_of
from risk_env.risk.exact_kernel import disc_probability_batch, disc_probability_scalar
from risk_env.risk.monte_carlo import MIN_WIDTH as MIN_WIDTH
from risk_env.risk.monte_carlo import MonteCarloRisk
from risk_env.risk.quadrature import GAUSS_NODES as GAUSS_NODES
from risk_env.risk.quadrature import (
    GEOMETRY_FLOOR,
    SOLVER_SHORTFALL,
    SOLVER_SIGMA_BREAKS,
    SOLVER_SUPPORT,
)
from risk_env.risk.worst_case import WorstCaseRisk
from risk_env.scenario.scenario import Scenario

_BELIEF_FIELDS = tuple(f.name for f in dataclasses.fields(Belief))
ESTIMATOR_NAMES: tuple[str, ...] = ("exact", "monte_carlo", "worst_case", "grid")


SCALAR_LOOP_MAX = 8
"""Up to this many states near the box, :class:`ExactRisk` integrates them one by one with the
scalar kernel (~20 us each) rather than the batch kernel, whose fixed cost (~150 us) exceeds a few
scalar calls."""


class ExactRisk(RiskEstimator):
    r"""$R = P(\mathrm{disc})\, E[s]$: deterministic and smooth in the ego state.

    :meth:`casadi_margin`, what the SMPC constrains, integrates $P$ with the solver's rule: the
    env's cut at $\pm 5 \sigma$ of the outer axis (:data:`~risk_env.risk.quadrature.SOLVER_SUPPORT`; 54
    nodes, not 66, the others the same), whose $P$ falls below the env's by at most
    :data:`~risk_env.risk.quadrature.SOLVER_SHORTFALL` (5.7e-7), which it adds back wherever the disc
    meets the box: never below the env's $R$, above it by at most $5.7 \cdot 10^{-7} E[s]$ (0.02 J
    for the paper's severities). :meth:`casadi_risk` is the env's $R$ itself.
    """

    name = "exact"

    def _risk(self, ego, belief, ops, gate=True, **kwargs):
        x, y, th, v = ego_parts(ego)
        p = disc_probability(x - belief.x, y - belief.y, self.radius, belief, ops, gate)
        return p * self.severity.expected(v, th, belief, ops)

    def solver_risk(self, ego: ca.SX, belief: Belief) -> ca.SX:
        """The symbolic $R$ the SMPC constrains: $P$ by the solver's rule plus its shortfall (where
        the disc meets the box), times $E[s]$; at or above the env's $R$."""
        x, y, th, v = ego_parts(ego)
        dx, dy = x - belief.x, y - belief.y
        p = disc_probability(dx, dy, self.radius, belief, CASADI, False, SOLVER_SIGMA_BREAKS, SOLVER_SUPPORT)
        hx = ca.fmax(belief.half_x, GEOMETRY_FLOOR)
        hy = ca.fmax(belief.half_y, GEOMETRY_FLOOR)
        along, across = to_frame(dx, dy, belief.frame, CASADI)
        near = signed_box_distance(along, across, hx, hy, CASADI) < self.radius
        p = near * ca.fmin(p + SOLVER_SHORTFALL, 1.0)
        return p * self.severity.expected(v, th, belief, CASADI)

    def casadi_margin(self, ego, belief, epsilon, **kwargs):
        r"""$(\epsilon - R) / \mathrm{scale}$ with the solver's $R$ (:meth:`solver_risk`): conservative."""
        return (epsilon - self.solver_risk(ego, belief)) / self.severity.scale

    def risk(self, ego, belief, rng=None):
        r"""As :meth:`RiskEstimator.risk`; states whose disc misses the truncation box (cut to
        $\pm 7 \sigma$, :func:`~risk_env.risk.disc.support_halves`) get exactly 0 without quadrature (the
        same value the full formula gives), the rest are integrated by
        the numpy kernels of :mod:`risk_env.risk.exact_kernel` (equal to the generic form to rounding)."""
        ego = np.asarray(ego, dtype=float)
        fields = vars(belief)
        if ego.shape == (4,) and all(isinstance(fields[f], (float, int)) for f in _BELIEF_FIELDS):
            return np.asarray(self.risk_one(ego.tolist(), belief))
        x, y, th, v = ego_parts(ego)
        dx, dy = to_frame(x - belief.x, y - belief.y, fields["frame"])
        sx, sy, hx, hy = (floor_geometry(fields[f]) for f in ("sigma_x", "sigma_y", "half_x", "half_y"))
        near = signed_box_distance(dx, dy, *support_halves(sx, sy, hx, hy)) < self.radius
        shapes = {near.shape, *(shape_of(fields[f]) for f in _BELIEF_FIELDS)} - {()}
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
            scalars = {f: a for f, a in fields.items() if not shape_of(a)}
            arrays = {f: np.broadcast_to(a, shape).reshape(-1) for f, a in fields.items() if shape_of(a)}
            for i in range(out.size) if index is None else index.tolist():
                one = Belief.unchecked(**scalars, **{f: float(a[i]) for f, a in arrays.items()})
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
        near_belief = Belief.unchecked(**{f: pick(fields[f]) for f in _BELIEF_FIELDS})
        p *= self.severity.expected(pick(v), pick(th), near_belief, NUMPY)
        if index is None:
            return p.reshape(shape)
        out.reshape(-1)[index] = p
        return out

    def risk_one(self, ego, belief, rng=None):
        """As :meth:`RiskEstimator.risk_one`: the gate and $E[s]$ on the MATH face, $P$ by the scalar
        kernel (exactly 0 without integrating when the disc misses the truncation box). The
        offset in the belief's frame goes to the kernels, whose disc is rotation-invariant."""
        x, y, th, v = ego
        dx, dy = to_frame(x - belief.x, y - belief.y, belief.frame, MATH)
        hx = max(belief.half_x, GEOMETRY_FLOOR)
        hy = max(belief.half_y, GEOMETRY_FLOOR)
        sx = max(belief.sigma_x, GEOMETRY_FLOOR)
        sy = max(belief.sigma_y, GEOMETRY_FLOOR)
        if not signed_box_distance(dx, dy, *support_halves(sx, sy, hx, hy, MATH), MATH) < self.radius:
            return 0.0
        p = disc_probability_scalar(
            float(dx), float(dy), self.radius, float(sx), float(sy), float(hx), float(hy)
        )
        return p * float(self.severity.expected(v, th, belief, MATH))


def make_estimator(name: str, scenario: Scenario, **kwargs: Any) -> RiskEstimator:
    """The estimator called ``name`` (one of :data:`ESTIMATOR_NAMES`) for ``scenario``; around it
    :class:`~risk_env.risk.bodies.BodyRisk` where the ego or the object has several discs."""
    if name == "exact":
        return with_bodies(ExactRisk(scenario, **kwargs))
    if name == "monte_carlo":
        return with_bodies(MonteCarloRisk(scenario, **kwargs))
    if name == "worst_case":
        return with_bodies(WorstCaseRisk(scenario, **kwargs))
    if name == "grid":
        return with_bodies(WorstCaseRisk(scenario, grid=True, **kwargs))
    raise ValueError(f"unknown risk estimator {name!r}; expected one of {ESTIMATOR_NAMES}")
