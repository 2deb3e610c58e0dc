r"""Vehicles as several discs along their heading (:class:`BodyRisk`): the ego's discs
``scenario.ego.disc_offsets`` and the object's ``scenario.object.disc_offsets``, each of the
part's radius.

Every pair of an ego disc $i$ and an object disc $j$ is the paper's single-disc problem with the
ego's centre moved by $a_i$ along its heading and the object's mean by $b_j$ along its mean
heading (:attr:`~risk_env.prediction.belief.Belief.theta`), the collision distance $r_e + r_o$ of
the two discs. The bodies touch when any pair does, so

- the worst case takes the object's discs as its capsule (:func:`stretched`): its centres' box
  stretched by the half length $a_o$ of its segment of centres along its heading, the largest
  over the ego's discs against it (the distance to the nearest, the margin the least). The
  stretched box holds every centre of the object's discs and of the segment between them, whose
  discs cover the car as well: a superset of the nine pairs, at a third of their rows;
- Monte Carlo's expectation is the sum over the pairs: by Boole's inequality
  $E[1[\cup_{ij} C_{ij}]\, s] \le \sum_{ij} E[1[C_{ij}]\, s]$ for $s \ge 0$, an upper bound on the
  bodies' risk (pairs that overlap count twice);
- the exact expectation is $P(z \in \text{box})\, E[s]$ (:func:`capsule_box_probability`): the
  discs lie in capsules (each body's segment of disc centres, half length $a$, widened by its
  radius), the object's centre $z$ touches the ego's body only inside the Minkowski sum of the two
  capsules, and that lies inside its bounding box in the belief's frame, where the truncated
  Gaussian's two axes are independent: a product of two interval probabilities in closed form
  (an upper bound, cheaper than one disc's quadrature; the nine pairs' quadratures made the
  SMPC's NLP too large to build). For cars in parallel lanes the box is the capsules' sum
  itself but at its four rounded corners; crossing at right angles it is $2(a_e + a_o + r)$ wide
  where the cars' rectangles touch within $L + W$. Where every ego disc clears the object's
  capsule box (the worst case's clearance is positive, :meth:`BodyRisk.capsule_clearance`) no
  position the belief allows touches the ego, so the risk is 0 there, not the box's: the box's
  corners, and its growth with the ego's heading off the belief's frame, may hold much of the
  object's mass beside a car that cannot be hit (a third of it for an ego turned 0.2 rad past a
  car in the next lane). The SMPC's row, $\max(\text{clearance}, (\epsilon - R) / \mathrm{scale})
  \ge 0$, is this gated $R \le \epsilon$; the solver's smooth $R$ (:meth:`BodyRisk.solver_risk`) is
  the box's alone.

Either way a plan that keeps the bound below $\epsilon$ keeps the bodies' risk below $\epsilon$.

A car of length $L$ and width $W$ lies inside $n$ discs of radius
$\sqrt{(L / 2n)^2 + (W / 2)^2}$ (:func:`cover_radius`): at highway-env's 5 x 2 m cars and three
discs, 1.30 m, so two cars in adjacent lanes 4 m apart no longer touch, as two 2 m discs do.
"""

from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np

from risk_env.models.frame import to_frame
from risk_env.models.ops import CASADI, MATH, NUMPY, Ops
from risk_env.prediction.belief import Belief
from risk_env.risk.estimator import RiskEstimator, ego_parts
from risk_env.risk.quadrature import GEOMETRY_FLOOR
from risk_env.risk.worst_case import box_distance
from risk_env.scenario.scenario import Scenario

Offsets = tuple[float, ...]


def cover_radius(length: float, width: float, discs: int) -> float:
    """Radius [m] of ``discs`` equal discs along a ``length`` x ``width`` [m] rectangle that cover it."""
    return math.hypot(length / (2 * discs), width / 2)


def body_offsets(scenario: Scenario) -> tuple[Offsets, Offsets]:
    """The ego's and the (first) object's disc offsets [m] along their headings."""
    return scenario.ego.disc_offsets, scenario.object.disc_offsets


def _symbolic(a: Any) -> bool:
    return isinstance(a, (ca.SX, ca.MX))


def _cos_sin(angle: Any) -> tuple[Any, Any]:
    if _symbolic(angle):
        return ca.cos(angle), ca.sin(angle)
    return np.cos(angle), np.sin(angle)


def moved_ego(ego: Any, offset: float) -> Any:
    """Ego state(s) ``(c1, c2, theta, v)`` with the centre moved ``offset`` [m] along the heading:
    numpy ``(..., 4)``, a CasADi vector of 4 or a sequence of 4 floats (then a tuple)."""
    if offset == 0.0:
        return ego
    if isinstance(ego, np.ndarray):
        out = ego.astype(float, copy=True)
        out[..., 0] += offset * np.cos(ego[..., 2])
        out[..., 1] += offset * np.sin(ego[..., 2])
        return out
    if _symbolic(ego):
        return ca.vertcat(ego[0] + offset * ca.cos(ego[2]), ego[1] + offset * ca.sin(ego[2]), ego[2], ego[3])
    x, y, th, v = ego
    return (x + offset * math.cos(th), y + offset * math.sin(th), th, v)


def moved_belief(belief: Belief, offset: float) -> Belief:
    """``belief`` with its mean moved ``offset`` [m] along its mean heading (spreads, box and frame
    unchanged: every point of the body's disc moves with the body)."""
    if offset == 0.0:
        return belief
    c, s = _cos_sin(belief.theta)
    fields = vars(belief)
    return Belief.unchecked(**{**fields, "x": belief.x + offset * c, "y": belief.y + offset * s})


def stretched(belief: Belief, half_length: float) -> Belief:
    """``belief`` with its truncation box grown to hold every point within ``half_length`` [m] of a
    possible centre along the mean heading (its bounding box in the belief's frame)."""
    if half_length == 0.0:
        return belief
    c, s = _cos_sin(belief.theta - belief.frame)
    magnitude = ca.fabs if _symbolic(c) else np.abs
    fields = vars(belief)
    grown = {
        "half_x": belief.half_x + half_length * magnitude(c),
        "half_y": belief.half_y + half_length * magnitude(s),
    }
    return Belief.unchecked(**{**fields, **grown})


def moved_draws(draws: Any, offset: float, theta: Any) -> Any:
    """Monte Carlo draws ``(..., 3)`` of ``(c1, c2, v)`` moved ``offset`` [m] along ``theta`` [rad]."""
    if offset == 0.0 or draws is None:
        return draws
    c, s = _cos_sin(theta)
    if _symbolic(draws):
        return ca.horzcat(draws[:, 0] + offset * c, draws[:, 1] + offset * s, draws[:, 2])
    out = np.array(draws, dtype=float, copy=True)  # (..., 3) with theta broadcasting over ``...``
    out[..., 0] += offset * c
    out[..., 1] += offset * s
    return out


def interval_probability(lo: Any, hi: Any, sigma: Any, half: Any, ops: Ops) -> Any:
    r"""$P(lo \le z \le hi)$ for $z \sim N(0, \sigma^2)$ truncated to $[-h, h]$ (``half``), with
    floored spreads; 0 where the interval misses the truncation."""
    k = 1.0 / (math.sqrt(2.0) * sigma)
    lo, hi = ops.maximum(lo, -half), ops.minimum(hi, half)
    inside = ops.erf(hi * k) - ops.erf(lo * k)
    return ops.maximum(inside, 0.0) / (2.0 * ops.erf(half * k))


def capsule_box_probability(ego: Any, belief: Belief, a_ego: float, a_object: float, r: Any, ops: Ops) -> Any:
    r"""$P$ that the object's centre lies in the bounding box, in the belief's frame, of the Minkowski
    sum of the ego's capsule (centre segment of half length ``a_ego`` [m] along its heading) and the
    object's (``a_object`` along its mean heading), widened by ``r`` = $r_e + r_o$ [m]: an upper bound
    on the chance that the bodies touch (module docstring). ``ego`` ``(..., 4)`` or CasADi."""
    x, y, th, _ = ego_parts(ego)
    frame = belief.frame
    along, across = to_frame(x - belief.x, y - belief.y, frame, ops)
    ce, se = ops.abs(ops.cos(th - frame)), ops.abs(ops.sin(th - frame))
    co, so = ops.abs(ops.cos(belief.theta - frame)), ops.abs(ops.sin(belief.theta - frame))
    ex = a_ego * ce + a_object * co + r
    ey = a_ego * se + a_object * so + r
    sx = ops.maximum(belief.sigma_x, GEOMETRY_FLOOR)
    sy = ops.maximum(belief.sigma_y, GEOMETRY_FLOOR)
    hx = ops.maximum(belief.half_x, GEOMETRY_FLOOR)
    hy = ops.maximum(belief.half_y, GEOMETRY_FLOOR)
    px = interval_probability(along - ex, along + ex, sx, hx, ops)
    return px * interval_probability(across - ey, across + ey, sy, hy, ops)


class BodyRisk(RiskEstimator):
    r"""The risk between bodies of several discs: ``inner`` (a single-disc estimator) on every
    pair of an ego disc and an object disc (their offsets from ``inner.scenario``), the worst case
    the largest over the pairs, an expectation their sum (see the module). Everything not named
    here is ``inner``'s (radius of one disc pair, severity, scenario)."""

    def __init__(self, inner: RiskEstimator) -> None:
        if isinstance(inner, BodyRisk):
            raise TypeError("BodyRisk wraps a single-disc estimator, got a BodyRisk")
        self.inner = inner
        self.ego_offsets, self.object_offsets = body_offsets(inner.scenario)
        self.worst = not inner.smooth
        self.boxed = inner.name == "exact"  # the capsules' box (module docstring), not the pairs
        self.half_lengths = (max(map(abs, self.ego_offsets)), max(map(abs, self.object_offsets)))
        self.name = inner.name

    def __getattr__(self, name: str) -> Any:
        """The inner estimator's attributes (its scenario, severity, $r_e + r_o$ of one disc pair)."""
        if name == "inner":  # not yet set (copy, pickle): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    @property
    def smooth(self) -> bool:  # type: ignore[override]
        return self.inner.smooth

    def rebuilt(self, inner: RiskEstimator) -> BodyRisk:
        """The same bodies around another single-disc estimator (e.g. one with symbolic numbers)."""
        return BodyRisk(inner)

    def pairs(self, ego: Any, belief: Belief) -> list[tuple[Any, Belief, float]]:
        """``(moved ego, moved belief, object offset)`` for every pair of discs; the worst case:
        every ego disc against the object's capsule (:func:`stretched`, offset 0)."""
        if self.worst:
            capsule = stretched(belief, self.half_lengths[1])
            return [(moved_ego(ego, a), capsule, 0.0) for a in self.ego_offsets]
        bodies = [(b, moved_belief(belief, b)) for b in self.object_offsets]
        return [(moved_ego(ego, a), moved, b) for a in self.ego_offsets for b, moved in bodies]

    def _combine(self, values: list[Any], ops: Ops) -> Any:
        out = values[0]
        for value in values[1:]:
            out = ops.maximum(out, value) if self.worst else out + value
        return out

    def _boxed(self, ego: Any, belief: Belief, ops: Ops, gated: bool = True) -> Any:
        """The exact expectation's bound: the capsules' box probability times $E[s]$, and 0 where
        every ego disc misses the object's capsule (:meth:`capsule_clearance` > 0: the bodies cannot
        touch, while the box's corners may hold mass); ``gated=False``: the smooth product alone."""
        p = capsule_box_probability(ego, belief, *self.half_lengths, self.radius, ops)
        _, _, th, v = ego_parts(ego)
        value = p * self.severity.expected(v, th, belief, ops)
        if not gated:
            return value
        return ops.where(self.capsule_clearance(ego, belief, ops) > 0.0, 0.0 * value, value)

    def capsule_clearance(self, ego: Any, belief: Belief, ops: Ops = NUMPY) -> Any:
        """The least signed distance [m] from an ego disc's centre to the object's capsule box
        (:func:`stretched`), minus $r_e + r_o$: the worst case's clearance, > 0 where no object
        position the belief allows touches the ego."""
        capsule = stretched(belief, self.half_lengths[1])
        out = None
        for a in self.ego_offsets:
            d = box_distance(moved_ego(ego, a), capsule, ops)
            out = d if out is None else ops.minimum(out, d)
        return out - self.radius

    def _risk(self, ego: Any, belief: Belief, ops: Ops, **kwargs: Any) -> Any:
        if self.boxed:
            return self._boxed(ego, belief, ops)
        theta = belief.theta
        values = []
        for e, b, offset in self.pairs(ego, belief):
            moved = {k: moved_draws(v, offset, theta) if k == "samples" else v for k, v in kwargs.items()}
            values.append(self.inner._risk(e, b, ops, **moved))
        return self._combine(values, ops)

    def risk(
        self, ego: np.ndarray, belief: Belief, rng: np.random.Generator | None = None, **kwargs: Any
    ) -> np.ndarray:
        """As the inner estimator's ``risk``, over the pairs (Monte Carlo ``draws`` moved with the
        object's disc)."""
        ego = np.asarray(ego, dtype=float)
        if self.boxed:
            return np.asarray(self._boxed(ego, belief, NUMPY))
        values = []
        for e, b, offset in self.pairs(ego, belief):
            moved = {k: moved_draws(v, offset, belief.theta) for k, v in kwargs.items()}
            values.append(np.asarray(self.inner.risk(e, b, rng=rng, **moved)))
        return np.asarray(self._combine(values, NUMPY))

    def risk_one(self, ego: Any, belief: Belief, rng: np.random.Generator | None = None) -> float:
        if self.boxed:
            return float(self._boxed(tuple(ego), belief, MATH))
        values = [self.inner.risk_one(e, b, rng=rng) for e, b, _ in self.pairs(tuple(ego), belief)]
        return max(values) if self.worst else math.fsum(values)

    def casadi_margin(self, ego: ca.SX, belief: Belief, epsilon: Any, **kwargs: Any) -> ca.SX:
        r"""$\ge 0$ exactly when the bodies' risk meets $\epsilon$: the least of the pairs' worst-case
        margins; the exact box's $\max(\text{clearance}, (\epsilon - R) / \mathrm{scale})$ with its
        ungated $R$; else $(\epsilon - \sum R) / \mathrm{scale}$ with the inner estimator's solver risk."""
        if self.worst:
            pairs = self.pairs(ego, belief)
            margins = [self.inner.casadi_margin(e, b, epsilon, **kwargs) for e, b, _ in pairs]
            out = margins[0]
            for m in margins[1:]:
                out = ca.fmin(out, m)
            return out
        if self.boxed:  # the gate of :meth:`_boxed`: R <= epsilon or no ego disc near the capsule
            margin = (epsilon - self.solver_risk(ego, belief)) / self.severity.scale
            return ca.fmax(self.capsule_clearance(ego, belief, CASADI), margin)
        if hasattr(self.inner, "solver_risk"):
            return (epsilon - self.solver_risk(ego, belief)) / self.severity.scale
        return (epsilon - self.casadi_risk(ego, belief, **kwargs)) / self.severity.scale

    def solver_risk(self, ego: ca.SX, belief: Belief) -> ca.SX:
        """The solver's bound on the bodies' risk: the exact one's box (:meth:`_risk`), else the inner
        estimator's solver risk summed over the pairs (module docstring)."""
        if self.boxed:
            return self._boxed(ego, belief, CASADI, gated=False)
        values = [self.inner.solver_risk(e, b) for e, b, _ in self.pairs(ego, belief)]
        return self._combine(values, CASADI)

    def distance(self, ego: Any, belief: Belief, ops: Ops = NUMPY) -> Any:
        """Distance [m] from the nearest ego disc centre to the object's capsule's box (the worst-case
        estimators' :meth:`~risk_env.risk.worst_case.WorstCaseRisk.distance`, the least over the
        ego's discs)."""
        values = [self.inner.distance(e, b, ops) for e, b, _ in self.pairs(ego, belief)]
        out = values[0]
        for value in values[1:]:
            out = ops.minimum(out, value)
        return out

    def distances(self, ego: Any, samples: Any, theta: Any = 0.0) -> Any:
        """CasADi: the distances from every ego disc to every object disc of the draws
        ``samples (J, 3)`` (object discs along ``theta`` [rad]), stacked ``(pairs J,)``."""
        rows = [
            self.inner.distances(moved_ego(ego, a), moved_draws(samples, b, theta))
            for a in self.ego_offsets
            for b in self.object_offsets
        ]
        return ca.vertcat(*rows)

    def __repr__(self) -> str:
        return f"BodyRisk({self.inner!r}, ego={self.ego_offsets}, object={self.object_offsets})"


def with_bodies(estimator: RiskEstimator) -> RiskEstimator:
    """``estimator`` itself when the ego and the object are one disc each (the paper), else a
    :class:`BodyRisk` around it."""
    if isinstance(estimator, BodyRisk):
        return estimator
    ego, obj = body_offsets(estimator.scenario)
    return estimator if len(ego) == len(obj) == 1 else BodyRisk(estimator)
