"""The risk-constrained path-following MPC: the controller (:mod:`~agents.mpc.controller`), its
robust and stochastic forms (:mod:`~agents.mpc.rmpc`, :mod:`~agents.mpc.smpc`), the object slots,
the step pipeline with its graceful degradation (:mod:`~agents.mpc.step`,
:mod:`~agents.mpc.attempts`, :mod:`~agents.mpc.guesses`, :mod:`~agents.mpc.fallback`) and the NLP
with its solver (:mod:`agents.mpc.nlp`)."""

from agents.mpc.controller import SOLVERS, STAGE_COSTS, PathFollowingMPC
from agents.mpc.rmpc import RMPC
from agents.mpc.smpc import SMPC

__all__ = ["RMPC", "SMPC", "SOLVERS", "STAGE_COSTS", "PathFollowingMPC"]
