"""Faces of the same elementary maths: numpy (vectorised), CasADi (symbolic) and Python floats.

Every model in :mod:`risk_env` is written once against an :class:`Ops` namespace, so the
simulator, the env's risk report and the MPC's constraints evaluate the very same formulas.
:data:`MATH` (the ``math`` module on Python floats) serves one state where numpy's per-call cost
(about 1 us, against 30-100 ns for ``math``) would dominate: the single env's step (dynamics,
path, prediction, observation, reward) and one ego state's expected severity. Its vectors are plain
lists, so vector maths with arithmetic on whole vectors (the disc probability) needs :data:`NUMPY`
or :data:`CASADI`; ``elementwise`` maps a scalar formula over them instead.
Both faces avoid evaluating singular expressions in an unused branch (``sin(a)/a`` at 0, ``acos``
at 1), so values and gradients stay finite everywhere.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from scipy import special

_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_HOLD = 2.0**50
"""Grid of :meth:`Ops.stop_derivative` (CasADi): |a| * 2**50 < 2**52 keeps the rounding exact."""


@dataclass(frozen=True)
class Ops:
    """The elementary functions a model may use; ``xp`` names the backend."""

    name: str
    sin: Callable[[Any], Any]
    cos: Callable[[Any], Any]
    exp: Callable[[Any], Any]
    sqrt: Callable[[Any], Any]
    erf: Callable[[Any], Any]
    asin: Callable[[Any], Any]
    acos: Callable[[Any], Any]
    atan2: Callable[[Any, Any], Any]
    abs: Callable[[Any], Any]
    floor: Callable[[Any], Any]
    maximum: Callable[[Any, Any], Any]
    minimum: Callable[[Any, Any], Any]
    where: Callable[[Any, Any, Any], Any]

    stack: Callable[[list[Any]], Any]
    """Scalars (or batch arrays) -> a vector on a last axis (numpy) / a column (CasADi)."""
    expand: Callable[[Any], Any]
    """A batch scalar made to broadcast against such a vector."""
    stack_vectors: Callable[[list[Any]], Any]
    """Vectors joined end to end."""
    sort: Callable[[Any], Any]
    """Ascending sort of a vector."""
    sum: Callable[[Any], Any]
    """Sum over the vector axis."""
    part: Callable[[Any, slice], Any]
    """Entries of a vector: ``part(v, slice(1, None))``, or one entry as a batch scalar."""
    repeat: Callable[[Any, int], Any]
    """Each entry of a vector repeated ``k`` times in a row."""
    const: Callable[[np.ndarray], Any]
    """A constant numpy vector in this backend."""
    hypot: Callable[[Any, Any], Any]
    r"""$\sqrt{x^2 + y^2}$, without overflow."""
    norm_ppf: Callable[[Any], Any]
    r"""The standard normal quantile $\Phi^{-1}(p)$, $-\infty$ at 0 and $\infty$ at 1."""
    elementwise: Callable[..., Any]
    """``elementwise(f, *vectors)``: the scalar formula ``f`` applied entry by entry (numpy and
    CasADi broadcast; Python floats go through the lists)."""
    pack: Callable[[list[Any]], np.ndarray]
    """Scalars (or batch arrays ``(B,)``) -> a new float64 numpy array with them on a last axis,
    ``(..., len(values))`` in C order: how a model's values leave for the caller."""

    def clip(self, x: Any, lo: Any, hi: Any) -> Any:
        return self.minimum(self.maximum(x, lo), hi)

    def sinc(self, a: Any) -> Any:
        r"""$\sin(a)/a$, smooth and exact through $a = 0$: below $|a| = 10^{-4}$ its Taylor polynomial,
        whose error there ($a^4/120 < 10^{-18}$) is below rounding. numpy arrays take $\sin(a)/a$ all the way
        down to 0 (within an ulp of the polynomial; a third of its numpy calls)."""
        if type(a) is float:  # the formula below, spelled for one float (no face lookups)
            return math.sin(a) / a if abs(a) >= 1e-4 else 1.0 - a * a / 6.0
        if isinstance(a, np.ndarray) and a.ndim:
            if a.all():
                return np.sin(a) / a
            return np.divide(np.sin(a), a, out=np.ones_like(a), where=a != 0.0)
        small = self.abs(a) < 1e-4
        a_safe = self.where(small, 1.0, a)
        return self.where(small, 1.0 - a * a / 6.0, self.sin(a_safe) / a_safe)

    def norm_cdf(self, z: Any) -> Any:
        r"""Standard normal CDF $\Phi(z)$."""
        if self.name == "numpy":
            return special.ndtr(z)
        if self.name == "math":  # erfc keeps the lower tail's relative precision, as ndtr does
            return 0.5 * math.erfc(-z / _SQRT2)
        return 0.5 * (1.0 + self.erf(z / _SQRT2))

    def norm_pdf(self, z: Any) -> Any:
        """Standard normal density phi(z)."""
        return _INV_SQRT_2PI * self.exp(-0.5 * z * z)

    def wrap_angle(self, a: Any) -> Any:
        """a wrapped to [-pi, pi)."""
        return a - 2.0 * math.pi * self.floor((a + math.pi) / (2.0 * math.pi))

    def select(self, c: Any, a: Any, b: Any) -> Any:
        r"""``a`` where ``c`` else ``b``, for finite ``a`` and ``b``. CasADi writes it as the sum
        $c\, a + (1 - c)\, b$ (a comparison has no derivative), so derivatives follow one
        expression rather than both branches of a conditional; numpy and math use ``where``."""
        if self.name == "casadi":
            return c * a + (1 - c) * b
        return self.where(c, a, b)

    def stop_derivative(self, a: Any) -> Any:
        """``a`` held constant under differentiation, for ``|a| < 4``. CasADi rounds it to a
        multiple of 2**-50 (``floor`` has a zero derivative): within 4.5e-16 of ``a``, and no
        derivative flows back into ``a``. numpy and math have no derivatives: ``a`` itself."""
        if self.name == "casadi":
            return ca.floor(a * _HOLD + 0.5) / _HOLD
        return a


def _np_where(c: Any, a: Any, b: Any) -> Any:
    if isinstance(c, (bool, np.bool_)):  # scalar fast path: np.where costs ~3 us per call
        return a if c else b
    return np.where(c, a, b)


def _batch_shape(values: list[Any] | tuple[Any, ...]) -> tuple[int, ...]:
    """The broadcast shape of scalars and arrays (cheap for the usual mix of () and (B,))."""
    shapes = {getattr(v, "shape", ()) for v in values}
    if len(shapes) == 1:
        return shapes.pop()
    shapes.discard(())
    return shapes.pop() if len(shapes) == 1 else np.broadcast_shapes(*shapes)


def _np_stack(values: list[Any]) -> np.ndarray:
    """``values`` on a new last axis, their batch shapes broadcast (by assignment: a third of
    ``np.stack``'s cost on small arrays)."""
    if all(type(v) is float for v in values):
        return np.array(values)
    dtype = np.float64
    if not all(type(v) is float or getattr(v, "dtype", None) == dtype for v in values):
        dtype = np.result_type(*values)
    out = np.empty((*_batch_shape(values), len(values)), dtype=dtype)
    for i, v in enumerate(values):
        out[..., i] = v
    return out


def _np_pack(values: list[Any]) -> np.ndarray:
    """``values`` as a new C-ordered float64 array ``(*batch, len(values))``."""
    shape = _batch_shape(values)
    if shape and all(type(v) is np.ndarray and v.shape == shape for v in values):
        rows = np.array(values, dtype=float)  # one call for equal arrays
    else:
        rows = np.empty((len(values), *shape))
        for i, v in enumerate(values):
            rows[i] = v
    if not shape:
        return rows
    if len(shape) == 1:
        return rows.T.copy()
    return np.ascontiguousarray(np.moveaxis(rows, 0, -1))


_NORMAL = statistics.NormalDist()


def _math_norm_ppf(p: float) -> float:
    r"""$\Phi^{-1}(p)$ by Wichura's AS241 (within ~1e-15 relative of scipy's ndtri)."""
    if 0.0 < p < 1.0:
        return _NORMAL.inv_cdf(p)
    return -math.inf if p <= 0.0 else math.inf


def _np_join(vectors: list[np.ndarray]) -> np.ndarray:
    """Vectors joined on the last axis, their batch shapes broadcast."""
    try:
        return np.concatenate(vectors, axis=-1)
    except ValueError:
        batch = np.broadcast_shapes(*(np.shape(v)[:-1] for v in vectors))
        return np.concatenate([np.broadcast_to(v, batch + np.shape(v)[-1:]) for v in vectors], -1)


def _ca_sort(v: Any) -> Any:
    """Odd-even transposition network: smooth almost everywhere, n rounds of fmin/fmax."""
    e = [v[i] for i in range(v.shape[0])]
    n = len(e)
    for i in range(n):
        for j in range(i % 2, n - 1, 2):
            e[j], e[j + 1] = ca.fmin(e[j], e[j + 1]), ca.fmax(e[j], e[j + 1])
    return ca.vertcat(*e)


NUMPY = Ops(
    name="numpy",
    sin=np.sin,
    cos=np.cos,
    exp=np.exp,
    sqrt=np.sqrt,
    erf=special.erf,
    asin=np.arcsin,
    acos=np.arccos,
    atan2=np.arctan2,
    abs=np.abs,
    floor=np.floor,
    maximum=np.maximum,
    minimum=np.minimum,
    where=_np_where,
    stack=_np_stack,
    stack_vectors=_np_join,
    expand=lambda a: np.asarray(a)[..., None],
    sort=lambda v: np.sort(v, axis=-1),
    sum=lambda v: np.sum(v, axis=-1),
    part=lambda v, s: v[..., s],
    repeat=lambda v, k: np.repeat(v, k, axis=-1),
    const=lambda c: c,
    hypot=np.hypot,
    norm_ppf=special.ndtri,
    elementwise=lambda f, *vectors: f(*vectors),
    pack=_np_pack,
)

CASADI = Ops(
    name="casadi",
    sin=ca.sin,
    cos=ca.cos,
    exp=ca.exp,
    sqrt=ca.sqrt,
    erf=ca.erf,
    asin=ca.asin,
    acos=ca.acos,
    atan2=ca.atan2,
    abs=ca.fabs,
    floor=ca.floor,
    maximum=ca.fmax,
    minimum=ca.fmin,
    where=lambda c, a, b: ca.if_else(c, a, b),
    stack=lambda values: ca.vertcat(*values),
    stack_vectors=lambda vs: ca.vertcat(*vs),
    expand=lambda a: a,
    sort=_ca_sort,
    sum=ca.sum1,
    part=lambda v, s: v[s],
    repeat=lambda v, k: ca.kron(v, ca.DM.ones(k, 1)),
    const=ca.DM,
    hypot=lambda x, y: ca.sqrt(x * x + y * y),
    norm_ppf=lambda p: _SQRT2 * ca.erfinv(2.0 * p - 1.0),
    elementwise=lambda f, *vectors: f(*vectors),
    pack=lambda values: ca.vertcat(*values),
)

MATH = Ops(
    name="math",
    sin=math.sin,
    cos=math.cos,
    exp=math.exp,
    sqrt=math.sqrt,
    erf=math.erf,
    asin=math.asin,
    acos=math.acos,
    atan2=math.atan2,
    abs=abs,
    floor=math.floor,
    maximum=max,
    minimum=min,
    where=lambda c, a, b: a if c else b,
    stack=list,
    stack_vectors=lambda vs: [e for v in vs for e in v],
    expand=lambda a: a,
    sort=sorted,
    sum=math.fsum,
    part=lambda v, s: v[s],
    repeat=lambda v, k: [e for e in v for _ in range(k)],
    const=lambda c: c.tolist(),
    hypot=math.hypot,
    norm_ppf=_math_norm_ppf,
    elementwise=lambda f, *vectors: [f(*entries) for entries in zip(*vectors)],
    pack=lambda values: np.array(values, dtype=float),
)
