"""The stochastic MPC (paper Sec. V): the expected-risk constraint R_n|k <= epsilon, n = 1..N."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from agents.mpc import PathFollowingMPC
from risk_env.ops import CASADI
from risk_env.prediction import Belief
from risk_env.risk import ExactRisk, MonteCarloRisk, WorstCaseRisk
from risk_env.scenario import Scenario

FAR = 20.0
"""Offset [m] per axis beyond which a Monte Carlo draw is moved in to FAR (for smoothing 0.05 m; it
scales with the smoothing): its smoothed indicator is exp(-340) either way."""


class SMPC(PathFollowingMPC):
    """Path-following MPC under the expected risk R = E[I_C s] of every prediction step n = 1..N.

    ``risk="exact"`` (default): :class:`risk_env.risk.ExactRisk`, deterministic and smooth.

    ``risk="monte_carlo"``: the paper's estimator, :class:`risk_env.risk.MonteCarloRisk`, over
    ``samples`` draws per step n (default: the scenario's J = 500), drawn once per solve from the
    agent's own generator (``seed``; common random numbers across the solver's iterations,
    reproducible after :meth:`reset`) and passed as parameters; the indicator is a logistic of
    width ``smoothing`` [m]. The reported risk re-evaluates the plan with the hard indicator on
    the same draws.

    The constraint is written ``max(clearance, (epsilon - R)/scale) >= backoff``, and
    ``clearance >= backoff`` alone at epsilon = 0 (the core's ``"zero"`` variant). The clearance is
    the distance from the ego centre to where the object may be, minus ``r_e + r_o``: to the
    truncation box for the exact risk; to the draws for Monte Carlo, as a smooth soft minimum of
    the distances, below the nearest by at most ``smoothing * log(J)`` (0.31 m for J = 500). R
    vanishes wherever the clearance is positive, so this is R <= epsilon; but R's gradient vanishes
    with R, and R <= 0 has no interior, which stalls an interior-point solver, while the clearance
    keeps a gradient (and a truncated Gaussian puts ~1e-20 of mass near a box edge ten sigmas out:
    the unguarded exact constraint would let the plan into the box at epsilon = 0). So at
    epsilon = 0 the exact SMPC is the RMPC's box constraint, as it must be (P = 0 off the box), and
    the Monte Carlo SMPC keeps off every draw (it differs from the RMPC by the tails its draws
    miss).

    Monte Carlo in the solver is hard going: with J = 500 draws and a 0.05 m logistic the risk is a
    staircase of ~5 J steps over the plane (the draws lie ~0.4 m apart), and the paper's severity
    adds a kink per draw in the ego speed; expect many more iterations than with the exact risk,
    and occasional fallbacks.

    The severity model is the scenario's (``scenario.severity``). See
    :class:`agents.mpc.PathFollowingMPC` for the problem, solver options and the fallback (shifted
    previous plan, then braking; counted in :attr:`failures`, never raised).
    """

    RISK_METHODS = ("exact", "monte_carlo")
    ZERO_TOLERANCE_VARIANT = True

    def __init__(
        self,
        scenario: Scenario,
        risk: str = "exact",
        samples: int | None = None,
        smoothing: float = 0.05,
        **kwargs: Any,
    ) -> None:
        if risk not in self.RISK_METHODS:
            raise ValueError(f"unknown SMPC risk method {risk!r}; expected one of {self.RISK_METHODS}")
        if samples is not None and (isinstance(samples, bool) or int(samples) != samples or samples < 1):
            raise ValueError(f"samples must be an integer >= 1, got {samples!r}")
        self.risk_method = risk
        self._box = WorstCaseRisk(scenario)
        if risk == "exact":
            self.estimator = ExactRisk(scenario)
        else:
            self.estimator = MonteCarloRisk(scenario, samples=samples, smoothing=smoothing)
        super().__init__(scenario, **kwargs)

    @property
    def samples(self) -> int | None:
        """J, the Monte Carlo draws per step (None for the exact risk)."""
        return getattr(self.estimator, "samples", None)

    def _estimator_key(self) -> tuple[Any, ...]:
        if self.risk_method == "exact":
            return ("exact",)
        return ("monte_carlo", self.estimator.samples, self.estimator.smoothing)

    def _risk_parameter_shape(self) -> tuple[int, int]:
        return (self.estimator.samples, 3) if self.risk_method == "monte_carlo" else (0, 0)

    def _margin(self, ego: ca.SX, belief: Belief, epsilon: ca.SX, data: ca.SX, zero: bool) -> ca.SX:
        if self.risk_method == "monte_carlo":
            # soft minimum of the distances to the draws: smooth, and below the minimum by at most
            # smoothing * log(J), so clearance >= 0 keeps the disc off every draw
            dx, dy = ego[0] - data[:, 0], ego[1] - data[:, 1]
            dist = ca.sqrt(dx * dx + dy * dy + 1e-12)
            t = self.estimator.smoothing
            nearest = ca.mmin(dist)  # shift for a safe exponent; the soft minimum's value and
            soft = nearest - t * ca.log(
                ca.sum1(ca.exp(-(dist - nearest) / t))
            )  # gradient do not depend on it
            clearance = soft - self.estimator.radius
        else:
            clearance = self._box.distance(ego, belief, CASADI) - self._box.radius
        if zero:  # R <= 0 <=> the disc misses every possible object position (box / draws)
            return clearance
        if self.risk_method == "monte_carlo":
            margin = self.estimator.casadi_margin(ego, belief, epsilon, samples=self._near(ego, data))
        else:
            margin = self.estimator.casadi_margin(ego, belief, epsilon)
        return ca.fmax(clearance, margin)  # R <= epsilon <=> clearance >= 0 or margin >= 0

    def _near(self, ego: ca.SX, data: ca.SX) -> ca.SX:
        """The draws with their offset from the ego clipped to +-:data:`FAR` per axis.

        MonteCarloRisk's logistic ``1 / (1 + exp((d - r) / smoothing))`` overflows (and its
        derivative turns NaN) for draws more than ~700 smoothing widths beyond the disc; draws that
        far contribute nothing, so moving them to FAR changes no value and keeps the gradients
        finite.
        """
        reach = FAR * self.estimator.smoothing / 0.05
        near = [ego[i] + ca.fmin(ca.fmax(data[:, i] - ego[i], -reach), reach) for i in range(2)]
        return ca.horzcat(*near, data[:, 2])

    def _risk_data(self, beliefs: Belief) -> np.ndarray:
        if self.risk_method != "monte_carlo":
            return super()._risk_data(beliefs)
        draws = beliefs.sample(self.rng, self.estimator.samples)  # (J, N, 3)
        return np.ascontiguousarray(np.moveaxis(draws, 0, 1))  # (N, J, 3)

    def _risk_numpy(self, ego: np.ndarray, beliefs: Belief, data: np.ndarray) -> np.ndarray:
        if self.risk_method == "monte_carlo":
            return self.estimator.risk(ego, beliefs, draws=np.moveaxis(data, 1, 0))
        return self.estimator.risk(ego, beliefs)
