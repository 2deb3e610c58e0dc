"""Collision severity models s(v_e, v_o), their expectation and their worst case.

Each model gives, written once for numpy and CasADi:

- ``value``: s for one object speed (Monte Carlo);
- ``expected``: E[s] when the object speed is a truncated Gaussian (exact estimator);
- ``worst``: max of s over a set of object speeds (robust estimators), given the set's end points
  and its element nearest to 0.

Speeds are signed, along each vehicle's heading [m/s]; headings [rad]; severities in J, except
the probability model (s = 1, dimensionless).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

from risk_env.ops import Ops
from risk_env.scenario import Scenario
from risk_env.truncnorm import SIGMA_FLOOR, partial_moments


class Severity(ABC):
    """A severity model; ``name`` is its key in :data:`risk_env.scenario.SEVERITY_NAMES`."""

    name: str
    unit: str = "J"

    @abstractmethod
    def value(self, v_e: Any, th_e: Any, v_o: Any, th_o: Any, ops: Ops) -> Any:
        """s at ego speed ``v_e`` and object speed ``v_o``."""

    def smooth_value(self, v_e: Any, th_e: Any, v_o: Any, th_o: Any, ops: Ops, width: float) -> Any:
        """s with its kinks rounded for a gradient-based solver: between ``value`` and
        ``value + width`` [units of s], equal to ``value`` for ``width = 0``. Models that are smooth
        already return ``value``."""
        return self.value(v_e, th_e, v_o, th_o, ops)

    @abstractmethod
    def expected(self, v_e: Any, th_e: Any, belief: Any, ops: Ops) -> Any:
        """E[s] over the belief's truncated-Gaussian speed."""

    @abstractmethod
    def worst(self, v_e: Any, th_e: Any, v_lo: Any, v_hi: Any, v_near0: Any, th_o: Any, ops: Ops) -> Any:
        """max of s over object speeds in a set with end points ``v_lo, v_hi`` and element
        ``v_near0`` closest to 0."""

    @property
    def scale(self) -> float:
        """A typical magnitude, to scale constraints for the solver."""
        return 1000.0


class PaperSeverity(Severity):
    """The paper's differential kinetic energy ``s = 0.5 |m_e v_e^2 - m_o v_o^2|`` [J] (eq. 13).

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
    """Energy lost in a perfectly plastic impact, ``0.5 m_e m_o/(m_e+m_o) |v_e - v_o|^2`` [J],
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
    unit = "-"

    def value(self, v_e, th_e, v_o, th_o, ops):
        return 1.0 + 0.0 * v_o

    def expected(self, v_e, th_e, belief, ops):
        return 1.0 + 0.0 * v_e

    def worst(self, v_e, th_e, v_lo, v_hi, v_near0, th_o, ops):
        return 1.0 + 0.0 * v_e

    @property
    def scale(self) -> float:
        return 1.0


def make_severity(scenario: Scenario) -> Severity:
    """The severity model named by ``scenario.severity``, with the scenario's masses."""
    m_e, m_o = scenario.ego.mass, scenario.object.mass
    if scenario.severity == "paper":
        return PaperSeverity(m_e, m_o)
    if scenario.severity == "plastic":
        return PlasticSeverity(m_e, m_o)
    return ProbabilitySeverity()
