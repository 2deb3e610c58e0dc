"""What a risk-constrained MPC defines (:class:`RiskForm`): its estimator, its risk rows and the
data they read; :class:`agents.RMPC` and :class:`agents.SMPC` fill it in, the controller
(:class:`agents.PathFollowingMPC`) calls it."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from agents.base import CallRecord
from risk_env.prediction.belief import Belief
from risk_env.risk.estimators import RiskEstimator
from risk_env.scenario.scenario import Scenario


class RiskForm:
    """The hooks of a risk form; the defaults are the "no risk data, no risk terms" ones."""

    def _estimator_key(self) -> tuple[Any, ...]:
        """What, besides the scenario and the solver settings, changes the built problem."""
        raise NotImplementedError

    def _estimator(self, scenario: Scenario) -> RiskEstimator:
        """The agent's estimator for one slot's single-object ``scenario``."""
        raise NotImplementedError

    def _risk_parameter_shape(self) -> tuple[int, int]:
        """Shape of the per-step risk data parameter ((0, 0): none)."""
        return (0, 0)

    def _margin(
        self, ego: ca.SX, beliefs: list[Belief], epsilon: ca.SX, data: ca.SX, numbers: ca.SX, zero: bool
    ) -> ca.SX:
        r"""Symbolic rows of one stage (:data:`agents.mpc.nlp.ocp.Margin`), each $\ge 0$ iff the risk bound
        holds at this step for every active slot; ``zero``: the form for $\epsilon = 0$ (only with
        :attr:`ZERO_TOLERANCE_VARIANT`)."""
        raise NotImplementedError

    def _pilot_plan(
        self, index: int, obs_vec: np.ndarray, variant: str, epsilon: float = 0.0
    ) -> tuple[np.ndarray, int, tuple[CallRecord, ...]] | None:
        """A cold start's first initial guess: inputs ``(N, NU)`` planned on a cheaper problem at
        the step's ``epsilon``, the solver iterations that took and its calls; None: start from the
        rollouts."""
        return None

    def _step_epsilon(self, index: int, new_episode: bool) -> float:
        r"""$\epsilon$ of batch entry ``index``'s step (``new_episode``: its memory was dropped): the
        agent's, unless a budget allocates it step by step (:class:`agents.SMPC`)."""
        return self._epsilon

    def _step_forms(self) -> set[str]:
        """The risk forms (hard variants but ``"free"``) a step may run: its tolerance's
        (:class:`agents.SMPC` with a budget: also those of the tolerances it may come down to)."""
        return {self._risk_variant()}

    def _risk_data(self, futures: list[Belief | None]) -> np.ndarray:
        """Per-step risk data ``(N, K J, 3)`` for one solve, the slots' blocks stacked (Monte
        Carlo: fresh draws for the present slots, zeros for the absent ones)."""
        return np.zeros((self.horizon, 0, 0))

    def _slot_risk(self, slot: int, ego: np.ndarray, belief: Belief, data: np.ndarray) -> np.ndarray:
        r"""Slot ``slot``'s risk ``(N,)`` of ego states ``(N, 4)`` against its beliefs at $n = 1, \dots, N$
        (``data``: its block ``(N, J, 3)``)."""
        raise NotImplementedError

    def _risk_terms(self) -> tuple[bool, bool]:
        """``(budget, weight)``: whether the NLP carries the episode risk budget and the weighted
        risk in its objective (:mod:`agents.mpc.nlp.risk_budget`); neither by default."""
        return (False, False)

    def _risk_value(self, ego: ca.SX, beliefs: list[Belief], data: ca.SX, numbers: ca.SX) -> ca.SX:
        """Symbolic R of one stage, the budget's and the cost's (with :meth:`_risk_terms`): the
        sum over the active slots (:data:`agents.mpc.nlp.ocp.RiskValue`)."""
        raise NotImplementedError

    def _terms_parameters(self, index: int, new_episode: bool) -> np.ndarray:
        """The risk terms' parameters (:data:`agents.mpc.nlp.parameters.TERMS`) of batch entry
        ``index`` (empty without terms); ``new_episode``: its memory was dropped."""
        return np.zeros(0)
