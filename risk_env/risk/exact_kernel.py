"""numpy kernels of the disc probability: :func:`risk_env.risk.estimators.disc_probability` made fast.

The generic form (one definition, shared with the MPC's CasADi constraints) builds the quadrature
from many small array operations: about 80 us for one ego state, 5 ms for 1,000. These kernels
evaluate the same integral on the same nodes (:mod:`risk_env.risk.quadrature`) and agree with it to
1e-12 (``tests/test_exact_kernel.py``):

- :func:`disc_probability_scalar`: one ego state; the segment set-up in Python floats, then one
  numpy pass over the 66 nodes;
- :func:`disc_probability_batch`: B ego states, arrays laid out (entries, B). Before the costly
  functions run it drops what adds nothing (segments of zero width or where the chord spans the
  inner box) and sorts the rest by how many chord ends need Phi (2, 1 or 0); sin and cos come
  from one vectorised tan, Phi from a table (:func:`_phi_table`).

Both take ego-minus-mean offsets ``(dx, dy)`` [m], the radius r = r_e + r_o [m], the standard
deviations ``(sx, sy)`` [m] and the box half widths ``(hx, hy)`` [m], floored to
:data:`~risk_env.risk.quadrature.GEOMETRY_FLOOR` by the caller, and assume that the disc meets the box
(off it, cut to +-SUPPORT sigma, the probability is exactly 0 and callers return that without
integrating: :func:`risk_env.risk.disc.support_halves`).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import special

from risk_env.risk.quadrature import EDGE, GAUSS_W, GAUSS_X, SEGMENTS, SIGMA_BREAKS, SUPPORT

_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_K = len(GAUSS_X)

# Nodes and weights are linear in the segment edges e (SEGMENTS + 1,): (t, w) = e @ _EDGES_TO_NODES, with
# t = lo (1 - x)/2 + hi (1 + x)/2 and w = (hi - lo) W/2 on each segment [lo, hi].
_EDGES_TO_NODES = np.zeros((SEGMENTS + 1, 2, SEGMENTS, _K))
for _s in range(SEGMENTS):
    _EDGES_TO_NODES[_s, 0, _s] = 0.5 * (1.0 - GAUSS_X)
    _EDGES_TO_NODES[_s + 1, 0, _s] = 0.5 * (1.0 + GAUSS_X)
    _EDGES_TO_NODES[_s, 1, _s] = -0.5 * GAUSS_W
    _EDGES_TO_NODES[_s + 1, 1, _s] = 0.5 * GAUSS_W
_EDGES_TO_NODES = _EDGES_TO_NODES.reshape(SEGMENTS + 1, 2 * SEGMENTS * _K)
_PLUS_MINUS = np.array([[1.0], [-1.0]])
# The outer axis' break points [-hx, hx, k sx ...] = hx _AT_H + sx _AT_S.
_AT_H = np.array([-1.0, 1.0] + [0.0] * len(SIGMA_BREAKS))
_AT_S = np.array([0.0, 0.0, *SIGMA_BREAKS])

# Phi(z) for the batch kernel, faster than scipy's ndtr (which takes 15-40 ns a value): a table
# at the multiples z0 of _PHI_STEP plus the integral of phi from z0 to z (|z - z0| <= 1/256) by
# 2-point Gauss-Legendre, whose error there is below 3e-17. Beyond +-_PHI_LIM, Phi is within
# 5.3e-17 of 0 or 1. Absolute error against ndtr: below 7e-16 (tests/test_exact_kernel.py).
_PHI_STEP = 1.0 / 128.0
_PHI_LIM = 8.3
_PHI_OFFSET = math.ceil(_PHI_LIM / _PHI_STEP)
_PHI_TABLE = special.ndtr(np.arange(-_PHI_OFFSET, _PHI_OFFSET + 1) * _PHI_STEP)
_PHI_GAUSS = (0.5 - 0.5 / math.sqrt(3.0), 0.5 + 0.5 / math.sqrt(3.0))


def _phi_table(u: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Phi(z) from ``u = z / _PHI_STEP + _PHI_OFFSET`` (any shape) into ``out``; beyond
    +-_PHI_LIM the table's end values stand in (within 5.3e-17)."""
    k = np.rint(u)
    d = np.subtract(u, k, out=u)  # (z - z0) / step
    index = k.astype(np.intp)
    k -= _PHI_OFFSET  # z0 / step
    acc = np.take(_PHI_TABLE, index, mode="clip", out=out)
    rest = np.multiply(d, _PHI_GAUSS[0])
    node = np.multiply(d, _PHI_GAUSS[1])
    for x in (rest, node):
        x += k
        x *= x
        x *= -0.5 * _PHI_STEP * _PHI_STEP
        np.exp(x, out=x)
    rest += node
    rest *= d
    rest *= 0.5 * _PHI_STEP * _INV_SQRT_2PI
    acc += rest
    return acc


def _norm_cdf(z: float) -> float:
    return 0.5 * math.erfc(-z / _SQRT2)


def _clip(u: float, lo: float, hi: float) -> float:
    return lo if u < lo else (hi if u > hi else u)


def disc_probability_scalar(
    dx: float, dy: float, r: float, sx: float, sy: float, hx: float, hy: float
) -> float:
    """P(||d - z|| <= r) for one ego state (floats in, a float out; see the module docstring)."""
    ex, ey = min(sx, hx), min(sy, hy)
    if (abs(dx) + ex) * (ex * ex) > (abs(dy) + ey) * (ey * ey):  # risk_env.risk.disc.outer_is_y
        dx, dy, sx, sy, hx, hy = dy, dx, sy, sx, hy, hx
    lim = SUPPORT * sx
    # Segment edges in the disc angle t: the outer range's ends (cut to where the chord meets the
    # inner box, within SUPPORT sigma) and breaks, then the chord's ends crossing the inner box
    # edges (r cos t = |hy -+ dy|), clipped to the range and sorted.
    meet = math.acos(_clip((abs(dy) - min(hy, SUPPORT * sy)) / r, 0.0, EDGE))
    ends = [math.asin(_clip((_clip(at, -lim, lim) - dx) / r, -EDGE, EDGE)) for at in (-hx, hx)]
    t_lo = max(ends[0], -meet)
    t_hi = max(min(ends[1], meet), t_lo)
    inner = [math.asin(_clip((_clip(k * sx, -lim, lim) - dx) / r, -EDGE, EDGE)) for k in SIGMA_BREAKS]
    for gap in (abs(hy - dy), abs(hy + dy)):
        a = math.acos(_clip(gap / r, 0.0, EDGE))
        inner += (a, -a)
    edges = [t_lo, *sorted(_clip(t, t_lo, t_hi) for t in inner), t_hi]

    tw = np.array(edges) @ _EDGES_TO_NODES
    t, w = tw[: SEGMENTS * _K], tw[SEGMENTS * _K :]
    cos_t = np.cos(t)
    # Phi at the chord's ends y = dy -+ r cos t, both clipped to the inner box (in units of sy).
    y = (_PLUS_MINUS * (r / sy)) * cos_t
    y += dy / sy
    h = hy / sy
    np.maximum(y, -h, out=y)
    np.minimum(y, h, out=y)
    special.ndtr(y, out=y)
    zx = math.erf(hx / (sx * _SQRT2))
    zy = math.erf(hy / (sy * _SQRT2))
    missed_y = zy - (y[0] - y[1])
    # phi(x / sx) at x = dx + r sin t
    g = np.sin(t)
    g *= r / sx
    g += dx / sx
    g *= g
    g *= -0.5
    np.exp(g, out=g)
    g *= cos_t
    g *= w
    missed = float(np.dot(g, missed_y)) * (r * _INV_SQRT_2PI / sx)
    mass = _norm_cdf((dx + r * math.sin(t_hi)) / sx) - _norm_cdf((dx + r * math.sin(t_lo)) / sx)
    return _clip((mass * zy - missed) / (zx * zy), 0.0, 1.0)


def _gather(value: np.ndarray | float, cols: np.ndarray | slice) -> np.ndarray | float:
    """``value[cols]`` for a per-state array, ``value`` itself for a scalar."""
    return value[cols] if np.ndim(value) else value


@functools.lru_cache(maxsize=8)
def _state_of_entry(n: int) -> np.ndarray:
    """The state (column) of each entry of a flattened ``(SEGMENTS, n)`` array (read-only)."""
    index = np.tile(np.arange(n), SEGMENTS)
    index.setflags(write=False)
    return index


def disc_probability_batch(
    dx: np.ndarray,
    dy: np.ndarray,
    r: float,
    sx: np.ndarray | float,
    sy: np.ndarray | float,
    hx: np.ndarray | float,
    hy: np.ndarray | float,
) -> np.ndarray:
    """P(||d - z|| <= r) for B ego states: ``dx, dy (B,)``; ``sx, sy, hx, hy`` each ``(B,)`` or
    a scalar (one belief for every state); returns ``(B,)``. See the module docstring."""
    n = dx.shape[0]
    # The outer axis (risk_env.risk.disc.outer_is_y); by symmetry only |dx| and |dy| matter (dy >= 0
    # below). Arrays are laid out (entries, B), so every ufunc's inner loop runs over the states.
    dx, dy = np.abs(dx), np.abs(dy)
    if np.ndim(sx) or np.ndim(sy) or np.ndim(hx) or np.ndim(hy) or sx != sy or hx != hy:
        ex, ey = np.minimum(sx, hx), np.minimum(sy, hy)
        swap = (dx + ex) * (ex * ex) > (dy + ey) * (ey * ey)
        sx, sy = np.where(swap, sy, sx), np.where(swap, sx, sy)
        hx, hy = np.where(swap, hy, hx), np.where(swap, hx, hy)
        dx, dy = np.where(swap, dy, dx), np.where(swap, dx, dy)
    else:  # one round belief: the axis of least offset
        dx, dy = np.minimum(dx, dy), np.maximum(dx, dy)

    # Segment edges (SEGMENTS + 1, B) in the disc angle t, as in disc_probability_scalar: sin t
    # at the outer range's ends and breaks first; the range cut to where the chord meets the box.
    lim = SUPPORT * sx
    at = np.asarray(np.clip(_AT_H[:, None] * hx + _AT_S[:, None] * sx, -lim, lim) / r) - dx / r
    np.maximum(at, -EDGE, out=at)
    np.minimum(at, EDGE, out=at)
    edges = np.empty((SEGMENTS + 1, n))
    np.arcsin(at[0], out=edges[0])
    np.arcsin(at[1], out=edges[-1])
    meet = np.arccos(np.clip((dy - np.minimum(hy, SUPPORT * sy)) / r, 0.0, EDGE))
    np.maximum(edges[0], -meet, out=edges[0])
    np.minimum(edges[-1], meet, out=edges[-1])
    np.maximum(edges[-1], edges[0], out=edges[-1])
    t_lo, t_hi = edges[0], edges[-1]
    inner = edges[1:-1]
    breaks = len(SIGMA_BREAKS)
    np.arcsin(at[2:], out=inner[:breaks])
    # Where the chord's ends cross the box edges: r cos t = |hy - dy| (the lower end leaves the
    # box above, or the upper end enters it) and hy + dy (the chord spans the box).
    a = inner[breaks : breaks + 2]
    np.abs(hy - dy, out=a[0])
    np.add(hy, dy, out=a[1])
    crosses = a < r * EDGE
    a /= r
    np.minimum(a, EDGE, out=a)
    np.arccos(a, out=a)
    a_leave, a_span = np.where(crosses, a, -1.0)
    np.negative(a, out=inner[breaks + 2 :])
    np.maximum(inner, t_lo, out=inner)
    np.minimum(inner, t_hi, out=inner)
    inner.sort(axis=0)

    # Segments by what they add, on the chord's ends y = dy -+ r cos t. Nothing: zero width, or
    # |t| < a_span, where the chord spans the box (zy - strip = 0). Where a_span <= |t| < a_leave
    # the upper end lies above the box (Phi(hy/sy) there) and the lower end in it. Where
    # |t| > a_leave both ends lie in the box if dy < hy, else above it (zy - strip = zy). The
    # break points make each segment one of these, so no end needs clipping to the box.
    # Columns below: [both ends' Phi | the lower end's | none].
    width = edges[1:] - edges[:-1]
    total = edges[1:] + edges[:-1]  # twice the middle
    mid_abs = np.abs(total)
    mid_abs *= 0.5
    keep = width > 0.0
    keep &= mid_abs >= a_span
    beyond = mid_abs > a_leave
    beyond &= keep
    keep &= ~beyond
    inside = dy < hy
    groups = [np.flatnonzero(beyond & inside), np.flatnonzero(keep), np.flatnonzero(beyond & ~inside)]
    n_two = len(groups[0])
    n_phi = n_two + len(groups[1])
    flat = np.concatenate(groups)
    cols = _state_of_entry(n)[flat]
    width = width.ravel()[flat]
    t_half = GAUSS_X[:, None] * (0.25 * width)  # t/2 at the nodes (nodes, segments kept)
    t_half += 0.25 * total.ravel()[flat]

    # sin t and cos t from u = tan(t/2) (numpy's tan is vectorised, its sin and cos are not).
    u = np.tan(t_half)
    c = np.multiply(u, u, out=t_half)
    c += 1.0
    np.divide(2.0, c, out=c)  # 1 + cos t
    u *= c  # sin t
    c -= 1.0  # cos t

    # zy - strip, strip = Phi(upper) - Phi(lower), with y / sy in the Phi table's units.
    unit = (1.0 / _PHI_STEP) / sy
    phi_box = special.ndtr(hy / sy)
    zy = special.erf(hy / (sy * _SQRT2))
    y_mid, y_half, zy_out = (
        _gather(v, cols[:n_phi]) for v in (dy * unit + _PHI_OFFSET, r * unit, zy - phi_box)
    )
    y_half = y_half * c[:, :n_phi]
    missed_y = np.empty_like(c)
    _phi_table(np.subtract(y_mid, y_half), out=missed_y[:, :n_phi])  # Phi(lower)
    missed_y[:, :n_phi] += zy_out
    missed_y[:, n_phi:] = _gather(zy, cols[n_phi:])
    if n_two:
        upper = y_half[:, :n_two]
        upper += _gather(y_mid, slice(0, n_two))
        missed_y[:, :n_two] += _gather(phi_box, cols[:n_two])
        missed_y[:, :n_two] -= _phi_table(upper)

    # The outer density at the nodes, times cos t, the missed inner mass and the weights.
    g = u
    g *= _gather(r / sx, cols)
    g += _gather(dx / sx, cols)
    g *= g
    g *= -0.5
    np.exp(g, out=g)  # sqrt(2 pi) phi(x / sx) at x = dx + r sin t
    g *= c
    g *= missed_y
    per_segment = np.einsum("j,jk->k", GAUSS_W, g)
    per_segment *= width
    # (bincount of no segments returns integers: multiply, not in place)
    missed = np.bincount(cols, weights=per_segment, minlength=n) * (0.5 * r * _INV_SQRT_2PI)

    # The outer mass over the range [t_lo, t_hi] in closed form.
    x_ends = np.sin(edges[[0, -1]])
    x_ends *= r
    x_ends += dx
    x_ends /= sx
    special.ndtr(x_ends, out=x_ends)
    mass = x_ends[1] - x_ends[0]
    zx = special.erf(hx / (sx * _SQRT2))
    p = mass * zy
    p -= missed / sx
    p /= zx * zy
    np.maximum(p, 0.0, out=p)
    return np.minimum(p, 1.0, out=p)
