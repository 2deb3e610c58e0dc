r"""The robust MPC (paper Sec. IV): the worst-case risk constraint $R_{wc,n|k} \le \epsilon$,
$n = 1, \dots, N$."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from agents.mpc.controller import PathFollowingMPC
from agents.mpc.nlp.parameters import INACTIVE
from agents.mpc.objects import symbolic
from risk_env.prediction.belief import Belief
from risk_env.risk.estimators import RiskEstimator, WorstCaseRisk
from risk_env.scenario.scenario import Scenario


class RMPC(PathFollowingMPC):
    r"""Path-following MPC under the worst-case risk of every prediction step $n = 1, \dots, N$.

    ``risk="worst_case"`` (default) uses the exact box form of
    :class:`risk_env.risk.estimators.WorstCaseRisk`:
    $\max(d - r, (\epsilon - s_{worst}) / \mathrm{scale}) \ge 0$ with the clearance $d - r$ the
    signed distance $d$ from the ego centre to the object's truncation box minus $r = r_e + r_o$,
    one row per object slot and stage (every object's worst case excluded; an inactive slot's row is
    lifted by :data:`agents.mpc.nlp.parameters.INACTIVE`); a tolerance above the worst severity over
    the speed interval relaxes it (with the paper's severity and a speed interval containing 0 that
    takes $\epsilon \ge$ 6250 J, so the paper's RMPC ignores $\epsilon$). ``risk="grid"`` is the
    paper's $L$-point grid under-approximation ($L$ = ``grid_points`` or the scenario's). Both are
    piecewise smooth (``fmax``); IPOPT copes.

    See :class:`agents.mpc.controller.PathFollowingMPC` for the problem, the solver options and the fallback
    (the soft problem, then the safest rate-limited manoeuvre; counted in :attr:`failures`, never
    raised) within the step's wall-time cap ``max_solve_time``.

    >>> from risk_env import Scenario
    >>> agent = RMPC(Scenario.preset("low"))            # doctest: +SKIP
    >>> action, _ = agent.predict(obs)                  # doctest: +SKIP
    """

    RISK_METHODS = ("worst_case", "grid")

    def __init__(
        self, scenario: Scenario, risk: str = "worst_case", grid_points: int | None = None, **kwargs: Any
    ) -> None:
        for name in ("risk_budget", "risk_weight"):
            if kwargs.get(name) is not None:
                raise ValueError(
                    f"{name}={kwargs[name]!r} given to the RMPC: its worst-case risk carries no"
                    " probability, so it has no expectation to budget or weigh (use the SMPC)"
                )
            kwargs.pop(name, None)
        if risk not in self.RISK_METHODS:
            raise ValueError(f"unknown RMPC risk method {risk!r}; expected one of {self.RISK_METHODS}")
        self.risk_method = risk
        self.grid_points = grid_points
        super().__init__(scenario, **kwargs)

    def _estimator(self, scenario: Scenario) -> RiskEstimator:
        return WorstCaseRisk(scenario, grid=(self.risk_method == "grid"), grid_points=self.grid_points)

    def _estimator_key(self) -> tuple[Any, ...]:
        return (self.risk_method, self.estimator.grid_points)

    def _margin(
        self, ego: ca.SX, beliefs: list[Belief], epsilon: ca.SX, data: ca.SX, numbers: ca.SX, zero: bool
    ) -> ca.SX:
        rows = []
        for k, belief in enumerate(beliefs):
            est = symbolic(self.estimators[k], numbers[k, 1], numbers[k, 2])
            rows.append(est.casadi_margin(ego, belief, epsilon) + INACTIVE * (1.0 - numbers[k, 0]))
        return ca.vertcat(*rows)

    def _slot_risk(self, slot: int, ego: np.ndarray, belief: Belief, data: np.ndarray) -> np.ndarray:
        return self.estimators[slot].risk(ego, belief)

    def clearance(self, ego: np.ndarray, beliefs: Belief) -> np.ndarray:
        """Distance [m] from ego centres ``(N, 4)`` to the first slot's truncation boxes minus
        $r_e + r_o$."""
        return self.estimator.distance(ego, beliefs) - self.estimator.radius
