"""The PPO baseline. :mod:`~agents.ppo.policy` acts: a trained policy reading observations only
(:class:`PPOAgent`); :mod:`~agents.ppo.training` is the env's view that trains it (imports the env)."""

from agents.ppo.policy import PPOAgent, shipped_model

__all__ = ["PPOAgent", "shipped_model"]
