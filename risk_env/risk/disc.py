"""The disc probability P(||q_e - q_o|| <= r) under the object's truncated 2-D Gaussian, and the
signed distance to its truncation box: the geometry of the exact risk
(:class:`risk_env.risk.estimators.ExactRisk`), written once for every face of
:mod:`risk_env.models.ops`.

A belief's covariance and truncation box lie in its own frame (:attr:`Belief.frame
<risk_env.prediction.belief.Belief.frame>`, the angle of its first axis from c1): the ego's offset is
turned into that frame (:func:`to_frame`), where the box is axis-aligned; the collision disc is
rotation-invariant, so the integral there is the one of an axis-aligned belief.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from risk_env.models.frame import to_frame
from risk_env.models.ops import NUMPY, Ops
from risk_env.prediction.belief import Belief
from risk_env.risk.quadrature import EDGE, GAUSS_W, GAUSS_X, GEOMETRY_FLOOR, SIGMA_BREAKS, SUPPORT

_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


def outer_is_y(dx: Any, dy: Any, sx: Any, sy: Any, hx: Any, hy: Any, ops: Ops = NUMPY) -> Any:
    """Whether the quadrature's outer axis is the second one (else the first), for offsets
    ``(dx, dy)`` in the belief's frame, floored spreads and half widths.

    Where the outer axis has its mass, the inner chord's ends sweep through the inner Gaussian at
    (e_out / e_in) |tan t| inner spreads per outer spread, tan t growing with the outer offset
    (|d_out| + e_out: the bulk's far side); the rule's breaks resolve the outer density, not that
    sweep. So the outer axis is the one of the smaller ``(|d| + e) e^2``, e = min(sigma, half
    width) the axis' effective spread: for a round belief the axis of least offset, for an
    elongated one mostly its narrow axis, but not where its far offset puts its mass at the
    disc's tangent."""
    ex, ey = ops.minimum(sx, hx), ops.minimum(sy, hy)
    return (ops.abs(dx) + ex) * (ex * ex) > (ops.abs(dy) + ey) * (ey * ey)


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
    ``[-half_x, half_x] x [-half_y, half_y]`` in the belief's frame; ``(dx, dy)`` = ego centre
    minus object mean [m] in the world, turned into the frame here (:func:`to_frame`).
    ``sigma_breaks`` and ``support``: the rule (:mod:`risk_env.risk.quadrature`; default the env's).

    One axis (the inner) is integrated in closed form with Phi, the other (the outer) by
    Gauss-Legendre quadrature in the disc angle t (x = dx + r sin t, which removes the
    square-root ends of the chord). Three choices make the rule exact for any aspect ratio
    (within 4e-6 of nested adaptive quadrature, ``python -m benchmarks.exact_accuracy``):

    - the outer axis (:func:`outer_is_y`) is the one along which the inner chord's ends sweep
      slowest through the inner Gaussian: for a round belief the axis of least offset (near the
      object the disc boundary runs along it, and its sharp crossing falls to the closed form),
      for an elongated one mostly its narrow axis (whose sharp density the breaks resolve);
    - the outer range is cut to where the chord meets the inner box (``r cos t >= |dy| - hy``,
      hy at most :data:`~risk_env.risk.quadrature.SUPPORT` inner sigmas): beyond, the chord
      misses the box (or all but < 3e-12 of the inner mass) and P gets nothing, and near the
      disc's tangent points the outer density, stretched in t, would otherwise be left to few
      nodes;
    - the outer integral is split where the box edges cut the disc and at fixed multiples of
      the outer standard deviation, with :data:`~risk_env.risk.quadrature.GAUSS_NODES` nodes each.

    Derivatives (the CasADi face) are those of the integral, not of where the rule puts its
    nodes: the segment edges are held constant (:meth:`~risk_env.models.ops.Ops.stop_derivative`),
    which is exact for the integral because the integrand is continuous across every interior
    edge (Leibniz's rule: the terms of a moving edge cancel between its two segments), and the
    motion of the outer range's two ends, where the integrand jumps to 0, enters through two
    extra nodes at the held ends whose weights are the ends' motion: 0 in value, Leibniz's term
    to second order in derivatives. Each node's term is then a product of a function of dx and
    one of dy, cheap to differentiate (figures of the earlier 4-node rule, the derivative scheme
    unchanged): the exact SMPC's Hessian of the Lagrangian takes 54 % fewer
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
    dx, dy = to_frame(dx, dy, belief.frame, ops)
    sx = ops.maximum(belief.sigma_x, GEOMETRY_FLOOR)
    sy = ops.maximum(belief.sigma_y, GEOMETRY_FLOOR)
    hx = ops.maximum(belief.half_x, GEOMETRY_FLOOR)
    hy = ops.maximum(belief.half_y, GEOMETRY_FLOOR)
    swap = outer_is_y(dx, dy, sx, sy, hx, hy, ops)
    dx, dy = ops.select(swap, dy, dx), ops.select(swap, dx, dy)  # one derivative path each
    sx, sy = ops.where(swap, sy, sx), ops.where(swap, sx, sy)
    hx, hy = ops.where(swap, hy, hx), ops.where(swap, hx, hy)
    ex = ops.expand

    # Angles where the outer coordinate meets a box edge or a multiple of its sigma ...
    at_x = ops.stack([-hx, hx, *(k * sx for k in sigma_breaks)])
    at_x = ops.clip(at_x, -support * ex(sx), support * ex(sx))
    t_x = ops.asin(ops.clip((at_x - ex(dx)) / r, -EDGE, EDGE))
    # ... cut to where the chord meets the inner box (within SUPPORT sigma) ...
    reach = ops.minimum(hy, SUPPORT * sy)
    meet = ops.acos(ops.clip((ops.abs(dy) - reach) / r, 0.0, EDGE))
    t_lo = ops.maximum(ops.part(t_x, slice(0, 1)), -ex(meet))
    t_hi = ops.maximum(ops.minimum(ops.part(t_x, slice(1, 2)), ex(meet)), t_lo)
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
    # above the chord 2 (Phi(hy) - Phi(top)), below it 2 (Phi(bottom) - Phi(-hy)), the ends
    # clipped to the box (the range is cut to where the chord meets it, so at most 2 zy).
    top, bottom = ops.minimum(top, ex(hy)), ops.maximum(bottom, -ex(hy))
    missed_twice = 2.0 * ex(zy) - ops.erf(top * ex(ky)) + ops.erf(bottom * ex(ky))
    u = x * ex(1.0 / (_SQRT2 * sx))
    missed = ops.sum(w * half_chord * ops.exp(-u * u) * missed_twice) * (0.5 * _INV_SQRT_2PI) / sx
    s_lo, s_hi = ops.sin(ops.part(t_lo, 0)), ops.sin(ops.part(t_hi, 0))
    x_lo, x_hi = dx + r * s_lo, dx + r * s_hi
    mass = ops.norm_cdf(x_hi / sx) - ops.norm_cdf(x_lo / sx)
    p = ops.clip((mass * zy - missed) / (zx * zy), 0.0, 1.0)
    if not gate:  # the caller passes only states whose disc meets the box
        return p
    # Exactly 0 when the disc misses the box cut to +-SUPPORT sigma.
    ux, uy = support_halves(sx, sy, hx, hy, ops)
    return ops.where(signed_box_distance(dx, dy, ux, uy, ops) < r, p, 0.0 * p)


def support_halves(sx: Any, sy: Any, hx: Any, hy: Any, ops: Ops = NUMPY) -> tuple[Any, Any]:
    """Half widths [m] of the box cut to +-:data:`~risk_env.risk.quadrature.SUPPORT` standard
    deviations (floored spreads and half widths in): where the disc misses it, P = 0 exactly (the
    mass left out is below 3e-12 per axis)."""
    return ops.minimum(hx, SUPPORT * sx), ops.minimum(hy, SUPPORT * sy)


def signed_box_distance(dx: Any, dy: Any, half_x: Any, half_y: Any, ops: Ops = NUMPY) -> Any:
    """Signed distance [m] from the point ``(dx, dy)`` to the box ``[-hx, hx] x [-hy, hy]``:
    Euclidean outside, minus the distance to the nearest edge inside."""
    qx = ops.abs(dx) - half_x
    qy = ops.abs(dy) - half_y
    ox, oy = ops.maximum(qx, 0.0), ops.maximum(qy, 0.0)
    outside = ops.sqrt(ox * ox + oy * oy + 1e-12) - 1e-6
    return outside + ops.minimum(ops.maximum(qx, qy), 0.0)
