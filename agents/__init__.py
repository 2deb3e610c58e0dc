"""Risk-constrained path-following MPC agents and the PPO baseline, with SB3's predictor protocol."""

from agents.base import FALLBACK_KINDS, Policy, SolveReport
from agents.mpc.controller import SOLVERS, STAGE_COSTS, PathFollowingMPC
from agents.mpc.rmpc import RMPC
from agents.mpc.smpc import SMPC
from agents.ppo.policy import PPOAgent

__all__ = [
    "FALLBACK_KINDS",
    "PPOAgent",
    "RMPC",
    "SMPC",
    "SOLVERS",
    "STAGE_COSTS",
    "PathFollowingMPC",
    "Policy",
    "SolveReport",
]
