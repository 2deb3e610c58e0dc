"""Train the PPO baseline on the vectorised RiskCrossing-v0 with a risk cost (stable-baselines3).

    python -m benchmarks.train_ppo --lagrangian --seeds 5 --out agents/models --name ppo_lagrangian
    python -m benchmarks.train_ppo --out agents/models --name ppo_penalty      # the shipped policies
    python -m benchmarks.train_ppo --lagrangian --scene two_crossing --total-timesteps 8000000 \
        --checkpoint-every 0 --out agents/models --name ppo_lagrangian_two_crossing   # two objects
    python -m benchmarks.train_ppo --total-timesteps 8192 --no-progress-bar   # one rollout, to results/ppo

The copies are split over the uncertainty levels and draw epsilon per episode; the policy is
told both (:class:`agents.ppo.policy.FeatureSpec`). Reward per step
(:class:`agents.ppo.training.RewardWeights`):
``-w_e ||e_{k+1}|| + w_p (lambda_{k+1} - lambda_k) + w_g [goal] - beta c_k``, with the cost
``c_k = max(0, R_{k+1|k} - epsilon) / cost_scale + collision_cost [collision]``. ``--lagrangian``
adapts beta after every rollout by dual ascent, ``beta <- max(0, beta + dual_lr (mean episode
cost - cost_limit))``. Writes ``OUT/NAME.zip`` and ``OUT/NAME.json`` (the arguments, input limits,
features, wall time and training throughput), checkpoints in ``OUT/NAME_checkpoints`` and SB3's
CSV log in ``OUT/NAME_logs``; :meth:`agents.ppo.policy.PPOAgent.load` reads the model back. ``--seeds N``
trains N seeds, scores them and ships the best (:func:`train_seeds`).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import json
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cli
from risk_env.scenario.scenes import SCENE_NAMES, scene_objects


@dataclass
class Args:
    """Every option of the training run (each is a ``--flag`` of the CLI)."""

    out: Path = Path("results/ppo")
    """Where the model, its metadata, checkpoints and logs go (the shipped policies are in
    agents/models: replace them only with an explicit ``--out agents/models``)."""
    name: str = "model"
    """File name of the model (``NAME.zip``, ``NAME.json``)."""
    total_timesteps: int = 4_000_000
    """Env steps to train for, over all copies; rounded up to whole rollouts of
    ``n_steps x num_envs`` env steps (PPO updates after each rollout)."""
    num_envs: int = 64
    """Copies of the env stepped as one batch."""
    seed: int = 0
    """Seed of the env copies, the policy's initialisation and its sampling."""
    seeds: int = 1
    """Train this many seeds (seed, seed + 1, ...): each is saved as ``OUT/NAME_seeds/NAME_seedS``
    and scored on sampled motion (``--eval-episodes``); the table of mean +- std goes to
    ``OUT/NAME_seeds.md`` (and ``.json``) and the best seed is copied to ``OUT/NAME.zip``."""
    uncertainty: str = "low,medium,high"
    """Comma list of the uncertainty presets trained on: the copies are split evenly over them."""
    tolerances: str = "0,500,1000,1500,2000,2500"
    """Comma list of epsilon [the severity's unit], one drawn per episode (the paper's Table II)."""
    conditioned: bool = True
    """Show the policy epsilon and the uncertainty (agents.ppo.policy.FeatureSpec)."""
    prediction: bool = True
    """Also show the object's predicted means and truncation boxes over the horizon."""
    forward_only: bool = True
    """Map the policy's actions to speeds v >= 0 (no reversing: unrestricted, PPO found reversing
    to the goal with the ego turned around, a local optimum of the path error)."""
    severity: str = "paper"
    """Severity of the risk in the cost (the paper's, in J, as Table II's epsilon)."""
    object_motion: str = "sampled"
    """How the object moves: ``"sampled"`` (draws from the prediction model) or ``"paper"``."""
    scene: str = "paper"
    """Which road users cross (risk_env.scenario.scenes): the policy sees every one of the scene's object
    slots (agents.ppo.policy.FeatureSpec ``slots``; one slot: the paper's features)."""
    randomize: bool = False
    """Train on seeded variations of the scenario (curvature, starts, object speed); off: the
    paper's scene with the object's motion sampled, the distribution the benchmarks score on."""
    w_path_error: float = 1.0
    """Reward per unit of the path error ||e_{k+1}|| (subtracted)."""
    w_progress: float = 2.0
    """Reward per m of progress along the path (lambda_{k+1} - lambda_k)."""
    w_goal: float = 30.0
    """Reward on reaching the goal."""
    cost_scale: float = 1000.0
    """Risk above epsilon per unit of cost [the severity's unit]."""
    collision_cost: float = 1.0
    """Cost of a collision [cost units]."""
    risk_weight: float = 300.0
    """beta: the penalty per unit of cost (the initial value with --lagrangian)."""
    penalty_warmup: int = 0
    """Env steps at beta = 0 before the penalty switches on (without --lagrangian): the policy
    first learns to drive, then to keep the risk down."""
    lagrangian: bool = False
    """Adapt beta by dual ascent toward cost_limit."""
    cost_limit: float = 0.02
    """Per-episode cost the Lagrangian aims at: the mean over the rollout's finished episodes of
    sum_k c_k (agents.ppo.training.RewardWeights: a collision counts collision_cost)."""
    dual_lr: float = 5.0
    """Step size of the dual ascent on beta [beta per unit of episode cost]."""
    n_steps: int = 128
    """Rollout length per copy between updates."""
    batch_size: int = 2048
    """Minibatch size of the PPO updates [env steps]."""
    n_epochs: int = 5
    """Passes over each rollout in the PPO update."""
    learning_rate: float = 3e-4
    """Adam step size."""
    gamma: float = 0.99
    """Discount factor."""
    gae_lambda: float = 0.95
    """lambda of generalised advantage estimation."""
    ent_coef: float = 0.0
    """Weight of the entropy bonus."""
    net_arch: tuple[int, ...] = (64, 64)
    """Hidden layer widths of the policy and value networks."""
    log_std_init: float = 0.0
    """Initial log standard deviation of the Gaussian policy (exploration at the start)."""
    normalize_reward: bool = True
    """Scale rewards by a running estimate of the return's spread (SB3's VecNormalize)."""
    checkpoint_every: int = 500_000
    """Save a checkpoint every this many env steps (0: none)."""
    progress_bar: bool = True
    """Show a progress bar (needs rich, part of the rl extra)."""
    eval_episodes: int = 512
    """Episodes of each seed's evaluation (sampled motion, medium uncertainty, --eval-epsilon)."""
    eval_epsilon: float = 0.0
    """epsilon of the evaluation [the severity's unit]."""


def field_help() -> dict[str, str]:
    """The docstring under each field of :class:`Args`, made plain: the help of its flag."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(Args)))
    body = tree.body[0].body
    helps: dict[str, str] = {}
    for node, after in zip(body, body[1:]):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            if isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant):
                helps[node.target.id] = cli.plain(str(after.value.value)).replace("\n", " ")
    return helps


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.train_ppo``: one ``--flag`` per field of :class:`Args`."""
    parser = cli.parser("train_ppo", __doc__)
    helps = field_help()
    choices = {
        "severity": ("paper", "plastic", "probability"),
        "object_motion": ("paper", "sampled"),
        "scene": SCENE_NAMES,
    }
    for f in dataclasses.fields(Args):
        flag = "--" + f.name.replace("_", "-")
        default = f.default
        text = helps[f.name]
        if isinstance(default, bool):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=default, help=text)
        elif isinstance(default, tuple):
            parser.add_argument(flag, type=int, nargs="+", default=list(default), help=text)
        else:
            parser.add_argument(
                flag, type=type(default), default=default, choices=choices.get(f.name), help=text
            )
    return parser


def parse_args(argv: list[str] | None = None) -> Args:
    """The CLI: one ``--flag`` per field of :class:`Args`."""
    parser = build_parser()
    args = Args(**vars(parser.parse_args(argv)))
    args.net_arch = tuple(args.net_arch)
    if args.total_timesteps < 1 or args.num_envs < 1 or args.n_steps < 1 or args.seeds < 1:
        parser.error("--total-timesteps, --num-envs, --n-steps and --seeds must be >= 1")
    bad = [u for u in levels(args) if u not in ("low", "medium", "high")]
    if bad or len(levels(args)) > args.num_envs:
        parser.error(f"--uncertainty must list low, medium, high (at most --num-envs of them), got {bad}")
    try:
        tolerances(args)
    except ValueError:
        parser.error(f"--tolerances must be numbers, got {args.tolerances!r}")
    return args


def levels(args: Args) -> list[str]:
    """The uncertainty presets of ``--uncertainty``."""
    return cli.comma_list(args.uncertainty)


def tolerances(args: Args) -> list[float]:
    """The epsilons of ``--tolerances``."""
    return [float(t) for t in cli.comma_list(args.tolerances)]


def feature_spec(args: Args, dt: float) -> Any:
    """The :class:`agents.ppo.policy.FeatureSpec` of the run (None: unconditioned, 14 features), with
    one slot per object of ``--scene``."""
    from agents.ppo.policy import FeatureSpec

    if not args.conditioned:
        if args.scene != "paper":
            raise ValueError("--no-conditioned sees one object only: train it on --scene paper")
        return None
    return FeatureSpec(prediction=args.prediction, dt=dt, slots=len(scene_objects(args.scene)))


def planned_timesteps(args: Args) -> int:
    """The env steps PPO will train: ``total_timesteps`` rounded up to whole rollouts.

    stable-baselines3 collects a full rollout (``n_steps`` steps of each of the ``num_envs``
    copies) before it checks the budget, so it trains a multiple of ``n_steps x num_envs``.
    """
    rollout = args.n_steps * args.num_envs
    return -(-args.total_timesteps // rollout) * rollout


def make_env(args: Args) -> Any:
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


def make_callbacks(args: Args) -> list[Any]:
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


def train(args: Args) -> dict[str, Any]:
    """Train, save ``OUT/NAME.zip`` and ``OUT/NAME.json``; returns the metadata written."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import configure

    from agents.ppo.policy import FEATURES, InputLimits

    torch.set_num_threads(1)  # small networks: threads cost more than they give on 2 cores
    args.out.mkdir(parents=True, exist_ok=True)
    venv = make_env(args)
    venv.seed(args.seed)
    spec = feature_spec(args, venv.get_attr("base_scenario")[0].dt)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        n_epochs=args.n_epochs,
        learning_rate=args.learning_rate,
        gamma=args.gamma,
        gae_lambda=args.gae_lambda,
        ent_coef=args.ent_coef,
        policy_kwargs={"net_arch": list(args.net_arch), "log_std_init": args.log_std_init},
        seed=args.seed,
        device="cpu",
    )
    model.set_logger(configure(str(args.out / f"{args.name}_logs"), ["stdout", "csv"]))
    callbacks = make_callbacks(args)
    start = time.perf_counter()
    model.learn(total_timesteps=args.total_timesteps, callback=callbacks)
    wall = time.perf_counter() - start
    model.save(args.out / f"{args.name}.zip")
    history = callbacks[0].history
    metadata = {
        "args": {k: (str(v) if isinstance(v, Path) else v) for k, v in dataclasses.asdict(args).items()},
        "limits": dataclasses.asdict(InputLimits.of(venv.get_attr("base_scenario")[0], args.forward_only)),
        "features": FEATURES if spec is None else spec.size,
        **({} if spec is None else {"feature_spec": dataclasses.asdict(spec)}),
        "timesteps": int(model.num_timesteps),
        "wall_time_s": round(wall, 1),
        "steps_per_s": round(model.num_timesteps / wall, 1),
        "final_rollout": history[-1] if history else {},
    }
    (args.out / f"{args.name}.json").write_text(json.dumps(metadata, indent=2) + "\n")
    venv.close()
    print(
        f"trained {model.num_timesteps} env steps in {wall:.1f} s ({metadata['steps_per_s']:,.0f} env steps/s"
        f" including updates); saved {args.out / (args.name + '.zip')}"
    )
    return metadata


def train_seeds(args: Args) -> dict[str, Any]:
    """Train ``args.seeds`` seeds, score each (:func:`benchmarks.ppo_eval.evaluate`), write the
    table ``OUT/NAME_seeds.md`` (and ``.json``) and copy the best seed to ``OUT/NAME.zip``/``.json``."""
    import shutil

    from benchmarks.ppo_eval import best_seed, evaluate, seed_table

    results: dict[int, dict[str, float]] = {}
    folder = args.out / f"{args.name}_seeds"
    walls: dict[int, dict[str, float]] = {}
    for seed in range(args.seed, args.seed + args.seeds):
        folder = args.out / f"{args.name}_seeds"
        one = dataclasses.replace(args, seed=seed, seeds=1, name=f"{args.name}_seed{seed}", out=folder)
        meta = train(one)
        walls[seed] = {"wall_time_s": meta["wall_time_s"], "steps_per_s": meta["steps_per_s"]}
        results[seed] = evaluate(
            folder / f"{one.name}.zip", args.eval_episodes, "medium", args.eval_epsilon, seed=0
        )
        print(f"seed {seed}: " + ", ".join(f"{k} {v:.4g}" for k, v in results[seed].items()))
    best = best_seed(results, args.cost_limit)
    for suffix in (".zip", ".json"):
        shutil.copyfile(folder / f"{args.name}_seed{best}{suffix}", args.out / f"{args.name}{suffix}")
    header = (
        f"{args.name}: {args.seeds} seeds x {planned_timesteps(args):,} env steps; each scored on"
        f" {args.eval_episodes} episodes (seeds 0..{args.eval_episodes - 1}), sampled motion, medium"
        f" uncertainty, epsilon {args.eval_epsilon:g}; shipped: seed {best}"
    )
    table = seed_table(results, best, header)
    (args.out / f"{args.name}_seeds.md").write_text(table)
    summary = {"best": best, "results": results, "training": walls}
    (args.out / f"{args.name}_seeds.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(table)
    return summary


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Parse the command line, say how many env steps will be trained, and train (every seed)."""
    args = parse_args(argv)
    planned = planned_timesteps(args)
    if planned != args.total_timesteps:
        print(
            f"--total-timesteps {args.total_timesteps} rounded up to {planned}: PPO trains whole rollouts"
            f" of n_steps x num_envs = {args.n_steps} x {args.num_envs} = {args.n_steps * args.num_envs}"
            " env steps"
        )
    return train(args) if args.seeds == 1 else train_seeds(args)


if __name__ == "__main__":
    main()
