"""The paper's Monte Carlo risk (eq. 16), :class:`MonteCarloRisk`: the mean of I_C s over J draws
of the belief (world coordinates, :meth:`~risk_env.prediction.belief.Belief.sample`), and its smoothed
CasADi form for the SMPC."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from risk_env.models.ops import CASADI, NUMPY, Ops
from risk_env.prediction.belief import Belief
from risk_env.risk.estimator import RiskEstimator, ego_parts
from risk_env.scenario.scenario import Scenario

MIN_WIDTH = 1e-3
"""Smallest width [m] of the Monte Carlo estimator's smoothed indicator (draws of a point mass)."""


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
        x, y, th, v = ego_parts(ego)
        draws = self._pad(draws, x)
        hit = np.hypot(x - draws[..., 0], y - draws[..., 1]) <= self.radius
        s = self.severity.value(v, th, draws[..., 2], belief.theta, NUMPY)
        return np.mean(hit * s, axis=0)

    def smoothing_bound(self, ego: np.ndarray, belief: Belief, draws: np.ndarray) -> np.ndarray:
        """Bound on ``|smoothed - hard|`` on the same ``draws (J, ..., 3)`` [units of the severity]:
        ``(1/J) sum_j exp(-|d_j - r| / h) s_j + w``."""
        ego = np.asarray(ego, dtype=float)
        x, y, th, v = ego_parts(ego)
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
        x, y, _, _ = ego_parts(ego)
        dx = x - samples[:, 0]
        dy = y - samples[:, 1]
        return ca.sqrt(dx * dx + dy * dy + 1e-12)

    def _risk(self, ego, belief, ops, samples=None, **kwargs):
        if samples is None:
            raise ValueError("the CasADi Monte Carlo risk needs samples=(J, 3) draws")
        _, _, th, v = ego_parts(ego)
        dist = self.distances(ego, samples)
        # logistic written with tanh: no overflow (and no NaN gradient) for far draws
        inverse = 0.5 / self.width(belief, CASADI)  # once, not per draw
        hit = 0.5 * (1.0 - ca.tanh((dist - self.radius) * inverse))
        s = self.severity.smooth_value(v, th, samples[:, 2], belief.theta, ops, self.severity_width)
        return ca.sum1(hit * s) / samples.shape[0]
