"""Collision severity models $s(v_e, v_o)$, their expectation and their worst case.

Each model gives, written once for numpy and CasADi:

- ``value``: $s$ for one object speed (Monte Carlo);
- ``expected``: $E[s]$ when the object speed is a truncated Gaussian (exact estimator);
- ``worst``: max of $s$ over a set of object speeds (robust estimators), given the set's end points
  and its element nearest to 0.

Speeds are signed, along each vehicle's heading [m/s]; headings [rad]; severities in J, except
the probability model ($s = 1$, dimensionless) and the injury model (expected number of seriously
injured people).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from risk_env.models.ops import NUMPY as NUMPY_OPS
from risk_env.models.ops import Ops
from risk_env.models.truncnorm import SIGMA_FLOOR, partial_moments
from risk_env.scenario.scenario import Scenario


class Severity(ABC):
    """A severity model; ``name`` is its key in :data:`risk_env.scenario.scenario.SEVERITY_NAMES`."""

    name: str
    unit: str = "J"
    """The unit of $s$, as tables name it."""

    @abstractmethod
    def value(self, v_e: Any, th_e: Any, v_o: Any, th_o: Any, ops: Ops) -> Any:
        """$s$ at ego speed ``v_e`` and object speed ``v_o``."""

    def smooth_value(self, v_e: Any, th_e: Any, v_o: Any, th_o: Any, ops: Ops, width: float) -> Any:
        """$s$ with its kinks rounded for a gradient-based solver: between ``value`` and
        ``value + width`` [units of $s$], equal to ``value`` for ``width = 0``. Models that are smooth
        already return ``value``."""
        return self.value(v_e, th_e, v_o, th_o, ops)

    @abstractmethod
    def expected(self, v_e: Any, th_e: Any, belief: Any, ops: Ops) -> Any:
        """$E[s]$ over the belief's truncated-Gaussian speed."""

    @abstractmethod
    def worst(self, v_e: Any, th_e: Any, v_lo: Any, v_hi: Any, v_near0: Any, th_o: Any, ops: Ops) -> Any:
        """max of $s$ over object speeds in a set with end points ``v_lo, v_hi`` and element
        ``v_near0`` closest to 0."""

    @property
    def scale(self) -> float:
        """A typical magnitude, to scale constraints for the solver."""
        return 1000.0

    @property
    def upper_bound(self) -> float:
        """The least upper bound of $s$ [units of $s$] (inf if unbounded): no risk, and so no
        sensible tolerance, exceeds it."""
        return math.inf


class PaperSeverity(Severity):
    r"""The paper's differential kinetic energy $s = \frac{1}{2} |m_e v_e^2 - m_o v_o^2|$ [J] (eq. 13).

    It vanishes when the kinetic energies match, whatever the directions.
    """

    name = "paper"

    def __init__(self, m_e: float, m_o: float) -> None:
        self.m_e, self.m_o = m_e, m_o

    def value(self, v_e, th_e, v_o, th_o, ops):
        return 0.5 * ops.abs(self.m_e * v_e * v_e - self.m_o * v_o * v_o)

    def smooth_value(self, v_e, th_e, v_o, th_o, ops, width):
        # 0.5 |z| -> 0.5 sqrt(z^2 + (2 width)^2): above 0.5 |z| by at most width, at z = 0
        if width <= 0:
            return self.value(v_e, th_e, v_o, th_o, ops)
        z = self.m_e * v_e * v_e - self.m_o * v_o * v_o
        return 0.5 * ops.sqrt(z * z + 4.0 * width * width)

    def expected(self, v_e, th_e, belief, ops):
        # Split |c^2 - V^2| at V = +-c, c = sqrt(m_e/m_o)|v_e|, and use truncated moments:
        # E|c^2 - V^2| = 2 (c^2 P_in - M2_in) - (c^2 - E[V^2]).
        c = ops.abs(v_e) * (self.m_e / self.m_o) ** 0.5
        sv = ops.maximum(belief.sigma_v, SIGMA_FLOOR)
        lo, hi = belief.v_lo, belief.v_hi
        p_in, _, m2_in = partial_moments(belief.speed, sv, lo, hi, -c, c, ops)
        _, _, m2 = partial_moments(belief.speed, sv, lo, hi, lo, hi, ops)
        c2 = c * c
        return 0.5 * self.m_o * (2.0 * (c2 * p_in - m2_in) - c2 + m2)

    def worst(self, v_e, th_e, v_lo, v_hi, v_near0, th_o, ops):
        e = self.m_e * v_e * v_e
        far = ops.maximum(v_lo * v_lo, v_hi * v_hi)
        return 0.5 * ops.maximum(ops.abs(e - self.m_o * far), ops.abs(e - self.m_o * v_near0 * v_near0))


class PlasticSeverity(Severity):
    r"""Energy lost in a perfectly plastic impact, $\frac{1}{2} \frac{m_e m_o}{m_e + m_o} |v_e - v_o|^2$ [J],
    with velocity vectors along each heading: zero only when the velocities are equal."""

    name = "plastic"

    def __init__(self, m_e: float, m_o: float) -> None:
        self.mu = m_e * m_o / (m_e + m_o)

    def _quadratic(self, v_e, th_e, m1, m2, th_o, ops):
        return 0.5 * self.mu * (v_e * v_e + m2 - 2.0 * v_e * m1 * ops.cos(th_e - th_o))

    def value(self, v_e, th_e, v_o, th_o, ops):
        return self._quadratic(v_e, th_e, v_o, v_o * v_o, th_o, ops)

    def expected(self, v_e, th_e, belief, ops):
        sv = ops.maximum(belief.sigma_v, SIGMA_FLOOR)
        lo, hi = belief.v_lo, belief.v_hi
        _, m1, m2 = partial_moments(belief.speed, sv, lo, hi, lo, hi, ops)
        return self._quadratic(v_e, th_e, m1, m2, belief.theta, ops)

    def worst(self, v_e, th_e, v_lo, v_hi, v_near0, th_o, ops):
        # Convex in v_o: the maximum sits at an end point.
        return ops.maximum(self.value(v_e, th_e, v_lo, th_o, ops), self.value(v_e, th_e, v_hi, th_o, ops))


class ProbabilitySeverity(Severity):
    """s = 1: the risk is the collision probability (dimensionless)."""

    name = "probability"
    unit = "probability"

    def value(self, v_e, th_e, v_o, th_o, ops):
        return 1.0 + 0.0 * v_o

    def expected(self, v_e, th_e, belief, ops):
        return 1.0 + 0.0 * v_e

    def worst(self, v_e, th_e, v_lo, v_hi, v_near0, th_o, ops):
        return 1.0 + 0.0 * v_e

    @property
    def scale(self) -> float:
        return 1.0

    @property
    def upper_bound(self) -> float:
        return 1.0


INJURY_NODES = 5
"""Gauss-Legendre nodes per segment of the injury severity's expectation."""
_INJURY_X, _INJURY_W = np.polynomial.legendre.leggauss(INJURY_NODES)
INJURY_BREAKS = (-5.0, -2.5, -1.0, 0.0, 1.0, 2.5, 5.0)
r"""Where the injury expectation's quadrature splits around the speed density's mode: where the
density has fallen by $\exp(-k^2 / 2)$, which is $k$ standard deviations for a mean inside the
truncation interval."""
INJURY_SUPPORT = 7.0
r"""The quadrature ends where the density has fallen by $\exp(-k^2 / 2)$, $k$ = ``INJURY_SUPPORT``
(< 3e-11)."""
KINK_GRADING = (1.0, 4.0, 16.0)
r"""Further splits at the least relative speed's object speed $\pm$ these multiples of the width of
its rounding: the relative speed is $\sqrt{(v_o - p)^2 + q^2}$, a kink of width $|q|$."""


_BREAKS = np.array(INJURY_BREAKS)
_GRADING = np.array([*(-g for g in KINK_GRADING[::-1]), 0.0, *KINK_GRADING])
_INJURY_SEGMENTS = len(_BREAKS) + len(_GRADING) + 1
_INJURY_XS = np.tile(_INJURY_X, _INJURY_SEGMENTS)
_INJURY_WS = np.tile(_INJURY_W, _INJURY_SEGMENTS)


class InjurySeverity(Severity):
    r"""Expected number of seriously (MAIS3+) injured people in the collision [injuries].

    The relative speed is the norm of the difference of the velocity vectors along each heading,
    $w = |v_e\, e(\theta_e) - v_o\, e(\theta_o)|$ [m/s]. A perfectly plastic impact (momentum
    conserved, one common velocity afterwards) changes each party's velocity by
    $\Delta v_e = \frac{m_o}{m_e + m_o} w$ and $\Delta v_o = \frac{m_e}{m_e + m_o} w$. Each party is
    seriously injured with the probability $p(\Delta v) = 1 / (1 + \exp(-(\beta_0 + \beta_1 \Delta v)))$
    (Geisslinger et al., "An ethical trajectory
    planning algorithm for autonomous vehicles", Nature Machine Intelligence 2023, the model without
    impact angle; ``scenario.injury_beta0``, ``injury_beta1``), so
    $s = p(\Delta v_e) + p(\Delta v_o)$. $s$ lies in $(0, 2)$ and grows with $w$; no collision is free
    ($2 p(0) = 0.020$ with the default coefficients).

    With $e(\theta) = (\cos \theta, \sin \theta)$ and $d = \theta_e - \theta_o$:
    $w^2 = (v_o - p)^2 + q^2$, $p = v_e \cos d$, $q = v_e \sin d$, so $w$ is convex in $v_o$, least
    at $v_o = p$ and has a kink there when the headings are parallel ($q = 0$).
    """

    name = "injury"
    unit = "injuries"

    def __init__(self, m_e: float, m_o: float, beta0: float, beta1: float) -> None:
        for label, value in (("injury_beta0", beta0), ("injury_beta1", beta1)):
            if not math.isfinite(value):
                raise ValueError(f"{label} must be finite, got {value!r}")
        if not beta1 > 0:
            raise ValueError(f"injury_beta1 [s/m] must be > 0 (harm grows with delta-v), got {beta1!r}")
        self.share_e, self.share_o = m_o / (m_e + m_o), m_e / (m_e + m_o)
        self.beta0, self.beta1 = float(beta0), float(beta1)

    def of_speed(self, w: Any, ops: Ops) -> Any:
        """$s$ at the relative speed ``w`` [m/s]: the two parties' injury probabilities."""
        b0, b1 = self.beta0, self.beta1
        p_e = 1.0 / (1.0 + ops.exp(-(b0 + b1 * self.share_e * w)))
        p_o = 1.0 / (1.0 + ops.exp(-(b0 + b1 * self.share_o * w)))
        return p_e + p_o

    def _of_square(self, w2: Any, ops: Ops) -> Any:
        """$s$ at the squared relative speed ``w2`` [m^2/s^2]. At $w = 0$, the norm's cone point, the
        gradient is taken as 0 (finite in every face)."""
        positive = w2 > 0.0
        return self.of_speed(ops.where(positive, ops.sqrt(ops.where(positive, w2, 1.0)), 0.0 * w2), ops)

    @staticmethod
    def _split(v_e: Any, th_e: Any, th_o: Any, ops: Ops) -> tuple[Any, Any]:
        """``(p, q)`` [m/s] with $w^2 = (v_o - p)^2 + q^2$."""
        d = th_e - th_o
        return v_e * ops.cos(d), v_e * ops.sin(d)

    def value(self, v_e, th_e, v_o, th_o, ops):
        p, q = self._split(v_e, th_e, th_o, ops)
        return self._of_square((v_o - p) * (v_o - p) + q * q, ops)

    def smooth_value(self, v_e, th_e, v_o, th_o, ops, width):
        # w -> sqrt(w^2 + c^2) <= w + c rounds the cone at w = 0; s is Lipschitz in w with constant
        # beta1 / 4 (a logistic's slope is at most 1/4 and the two shares sum to 1), so
        # c = 4 width / beta1 keeps s within [value, value + width].
        if width <= 0:
            return self.value(v_e, th_e, v_o, th_o, ops)
        c = 4.0 * width / self.beta1
        p, q = self._split(v_e, th_e, th_o, ops)
        return self.of_speed(ops.sqrt((v_o - p) * (v_o - p) + q * q + c * c), ops)

    def expected(self, v_e, th_e, belief, ops):
        r"""$E[s]$ over the truncated-Gaussian object speed by fixed Gauss-Legendre quadrature in
        $z = (v_o - \mu) / \sigma$: from the truncated density's mode to where it has fallen by
        $\exp(-k^2 / 2)$, $k$ = :data:`INJURY_SUPPORT`, within the truncation interval; split at
        :data:`INJURY_BREAKS` around the mode, at the least relative speed and around it
        (:data:`KINK_GRADING`); :data:`INJURY_NODES` nodes per segment; normalised by the
        quadrature's own mass, so a constant severity comes out exactly. Within 1e-8 of adaptive
        quadrature (``tests/test_severity.py``)."""
        if ops.name == "math":  # 75 nodes: numpy's vectors beat a loop over floats
            return float(self.expected(v_e, th_e, belief, NUMPY_OPS))
        mu = belief.speed
        sv = ops.maximum(belief.sigma_v, SIGMA_FLOOR)
        p, q = self._split(v_e, th_e, belief.theta, ops)
        ex = ops.expand
        a = (belief.v_lo - mu) / sv
        b = ops.maximum((belief.v_hi - mu) / sv, a)
        mode = ops.clip(0.0 * a, a, b)
        # The density falls by exp(-k^2 / 2) at k sigmas from a mean inside the interval; at
        # t = sqrt(r^2 + k^2) - r from the end for a mean r sigmas beyond it (~ exp(-r t - t^2/2)).
        r = ops.maximum(a, 0.0) + ops.maximum(-b, 0.0)
        reach = ops.sqrt(r * r + INJURY_SUPPORT**2) - r
        lo, hi = ops.maximum(a, mode - reach), ops.minimum(b, mode + reach)
        signs, squares = ops.const(np.sign(_BREAKS)), ops.const(_BREAKS * _BREAKS)
        at_mode = ex(mode) + signs * (ops.sqrt(ex(r * r) + squares) - ex(r))
        kink, width = (p - mu) / sv, ops.abs(q) / sv
        at_kink = ex(kink) + ex(width) * ops.const(_GRADING)
        inner = ops.sort(ops.clip(ops.stack_vectors([at_mode, at_kink]), ex(lo), ex(hi)))
        edges = ops.stack_vectors([ops.stack([lo]), inner, ops.stack([hi])])
        # INJURY_NODES nodes per segment on a vector axis, as risk.disc_probability lays them out
        left, right = ops.part(edges, slice(0, -1)), ops.part(edges, slice(1, None))
        half = ops.repeat(0.5 * (right - left), INJURY_NODES)
        z = ops.repeat(0.5 * (right + left), INJURY_NODES) + half * ops.const(_INJURY_XS)
        density = half * ops.const(_INJURY_WS) * ops.exp(-0.5 * (z - ex(mode)) * (z + ex(mode)))
        t = ex(sv) * (z - ex(kink))  # v_o - p
        total = ops.sum(density * self._of_square(t * t + ex(q * q), ops))
        mass = ops.sum(density)  # of phi(z) / phi(mode)
        # A zero-width interval is a point mass at the clipped mean.
        point = self.value(v_e, th_e, mu + sv * mode, belief.theta, ops)
        has_mass = mass > 0.0
        return ops.where(has_mass, total / ops.where(has_mass, mass, 1.0), point)

    def worst(self, v_e, th_e, v_lo, v_hi, v_near0, th_o, ops):
        # s grows with w, and w is convex in v_o: the maximum over an interval sits at an end.
        return ops.maximum(self.value(v_e, th_e, v_lo, th_o, ops), self.value(v_e, th_e, v_hi, th_o, ops))

    @property
    def scale(self) -> float:
        """0.01 injuries: the order of the tolerances (2 p(0) = 0.02 is the least harm of a
        collision), so the solver's backoff of 1e-3 margin units is 1e-5 injuries."""
        return 0.01

    @property
    def upper_bound(self) -> float:
        return 2.0


def make_severity(scenario: Scenario) -> Severity:
    """The severity model named by ``scenario.severity``, with the scenario's masses."""
    m_e, m_o = scenario.ego.mass, scenario.object.mass
    if scenario.severity == "paper":
        return PaperSeverity(m_e, m_o)
    if scenario.severity == "plastic":
        return PlasticSeverity(m_e, m_o)
    if scenario.severity == "injury":
        return InjurySeverity(m_e, m_o, scenario.injury_beta0, scenario.injury_beta1)
    return ProbabilitySeverity()


def check_tolerance(value: float, severity: str, what: str = "tolerance") -> float:
    r"""``value`` as a per-step risk bound in the unit of the severity named ``severity``: finite,
    $\ge 0$ and at most the severity's :attr:`~Severity.upper_bound` (a probability above 1 or more
    than 2 injuries per step is a value in another unit). Raises ``ValueError`` naming it."""
    model = make_severity(Scenario(severity=severity))
    value = float(value)
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f"{what} {value!r} must be finite and >= 0 [{model.unit}]")
    if value > model.upper_bound:
        raise ValueError(
            f"{what} {value:g} exceeds {model.upper_bound:g}, the largest per-step risk of the"
            f" {severity!r} severity [{model.unit}]: give it in that severity's own unit"
        )
    return value
