"""What a PPO training run of :mod:`benchmarks.train_ppo` is made of: the wrapper stack it trains
on (:func:`make_env`) and the callbacks that log its risk and adapt beta (:func:`make_callbacks`).
``args`` is a :class:`benchmarks.train_ppo.Args`."""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks import cli
from risk_env.scenario.scenes import scene_objects


def levels(args: Any) -> list[str]:
    """The uncertainty presets of ``--uncertainty``."""
    return cli.comma_list(args.uncertainty)


def tolerances(args: Any) -> list[float]:
    """The epsilons of ``--tolerances``."""
    return [float(t) for t in cli.comma_list(args.tolerances)]


def feature_spec(args: Any, dt: float) -> Any:
    """The :class:`agents.ppo.policy.FeatureSpec` of the run (None: unconditioned, 14 features), with
    one slot per object of ``--scene``."""
    from agents.ppo.policy import FeatureSpec

    if not args.conditioned:
        if args.scene != "paper":
            raise ValueError("--no-conditioned sees one object only: train it on --scene paper")
        return None
    return FeatureSpec(prediction=args.prediction, dt=dt, slots=len(scene_objects(args.scene)))


def make_env(args: Any) -> Any:
    """The wrapper stack: batched RiskCrossing-v0 copies split over the levels (LevelMix) ->
    PolicyView (features, epsilon per episode, the PPO reward) -> SB3 VecEnv -> VecMonitor
    (episode return, length, cost, collision, success) -> VecNormalize (rewards only)."""
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from agents.ppo.policy import InputLimits
    from agents.ppo.training import LevelMix, PolicyView, RewardWeights, SB3VecEnv

    env = LevelMix(
        args.num_envs,
        levels(args),
        severity=args.severity,
        object_motion=args.object_motion,
        randomize=args.randomize,
        scene=args.scene,
    )
    weights = RewardWeights(
        args.w_path_error, args.w_progress, args.w_goal, args.cost_scale, args.collision_cost
    )
    beta = 0.0 if args.penalty_warmup > 0 and not args.lagrangian else args.risk_weight
    view = PolicyView(
        env,
        InputLimits.of(env.base_scenario, args.forward_only),
        feature_spec(args, env.base_scenario.dt),
        weights,
        tolerances(args),
        risk_weight=beta,
        seed=args.seed,
    )
    venv = VecMonitor(SB3VecEnv(view), info_keywords=SB3VecEnv.EPISODE_KEYS)
    return VecNormalize(venv, norm_obs=False, norm_reward=args.normalize_reward, gamma=args.gamma)


def make_callbacks(args: Any) -> list[Any]:
    """Episode statistics (and beta's dual ascent with --lagrangian), checkpoints, progress bar."""
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback, ProgressBarCallback

    class RiskStats(BaseCallback):
        """Logs the episodes finished in each rollout: cost, collision and goal rates, beta; with
        ``lagrangian`` it then steps beta toward the cost limit (dual ascent)."""

        def __init__(self) -> None:
            super().__init__()
            self.episodes: list[dict[str, float]] = []
            self.history: list[dict[str, float]] = []
            self.terms: dict[str, float] = {}
            self.steps = 0

        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"]):
                for key, value in info["rewards"].items():
                    self.terms[key] = self.terms.get(key, 0.0) + float(value)
                self.steps += 1
                if done:
                    self.episodes.append(
                        {k: float(info[k]) for k in ("episode_cost", "collision", "is_success")}
                    )
            return True

        def _on_rollout_end(self) -> None:
            for key, total in self.terms.items():  # each reward term, mean per env step
                self.logger.record(f"reward/{key}", total / max(self.steps, 1))
            self.terms, self.steps = {}, 0
            beta = float(self.training_env.get_attr("risk_weight")[0])
            if not args.lagrangian and self.num_timesteps >= args.penalty_warmup and beta != args.risk_weight:
                beta = args.risk_weight  # the warm-up is over: the fixed penalty switches on
                self.training_env.set_attr("risk_weight", beta)
            if not self.episodes:
                return
            stats = {k: float(np.mean([e[k] for e in self.episodes])) for k in self.episodes[0]}
            self.logger.record("risk/episode_cost", stats["episode_cost"])
            self.logger.record("risk/collision_rate", stats["collision"])
            self.logger.record("risk/goal_rate", stats["is_success"])
            self.logger.record("risk/beta", beta)
            if args.lagrangian:
                beta = max(0.0, beta + args.dual_lr * (stats["episode_cost"] - args.cost_limit))
                self.training_env.set_attr("risk_weight", beta)
            self.history.append({**stats, "beta": beta, "timesteps": float(self.num_timesteps)})
            self.episodes = []

    callbacks: list[Any] = [RiskStats()]
    if args.checkpoint_every > 0:
        every = max(args.checkpoint_every // args.num_envs, 1)
        callbacks.append(
            CheckpointCallback(every, str(args.out / f"{args.name}_checkpoints"), name_prefix=args.name)
        )
    if args.progress_bar:
        callbacks.append(ProgressBarCallback())
    return callbacks
