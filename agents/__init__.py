"""Risk-constrained path-following MPC agents and the PPO baseline, with SB3's predictor protocol."""

from agents.base import FALLBACK_KINDS, Policy, SolveReport
from agents.mpc import SOLVERS, STAGE_COSTS, PathFollowingMPC
from agents.ppo import PPOAgent
from agents.rmpc import RMPC
from agents.smpc import SMPC

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
