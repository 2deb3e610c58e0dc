"""Train the PPO baseline on the vectorised RiskCrossing-v0 with a risk cost (stable-baselines3).

    python -m benchmarks.train_ppo --lagrangian --seeds 5 --out agents/models --name ppo_lagrangian
    python -m benchmarks.train_ppo --out agents/models --name ppo_penalty      # the shipped policies
    python -m benchmarks.train_ppo --lagrangian --scene two_crossing --total-timesteps 8000000 \\
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
import re
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchmarks import cli
from benchmarks.ppo_setup import feature_spec, levels, make_callbacks, make_env, tolerances
from risk_env.scenario.parts import UNCERTAINTY_PRESETS
from risk_env.scenario.scenes import SCENE_NAMES

__all__ = ["Args", "feature_spec", "levels", "main", "make_callbacks", "make_env", "parse_args", "tolerances"]
NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")
"""A model name: a plain file name (no folder, not hidden)."""
CHECKS: dict[str, Any] = {
    "seed": cli.nonnegative_int,
    "total_timesteps": cli.positive_int,
    "num_envs": cli.positive_int,
    "seeds": cli.positive_int,
    "n_steps": cli.positive_int,
    "batch_size": cli.positive_int,
    "n_epochs": cli.positive_int,
    "eval_episodes": cli.positive_int,
    "checkpoint_every": cli.nonnegative_int,
    "penalty_warmup": cli.nonnegative_int,
    "learning_rate": cli.positive_float,
    "gae_lambda": cli.unit_interval_closed,
    "gamma": cli.discount,
    "ent_coef": cli.nonnegative_float,
    "cost_scale": cli.positive_float,
    "collision_cost": cli.nonnegative_float,
    "risk_weight": cli.nonnegative_float,
    "dual_lr": cli.nonnegative_float,
    "eval_epsilon": cli.nonnegative_float,
}
"""The ``type=`` of each flag beyond its default's type (other floats: finite)."""


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
            parser.add_argument(
                flag,
                action=cli.CommaList,
                type=cli.numbers_list(cli.positive_int),
                default=",".join(map(str, default)),
                help=text,
            )
        elif f.name == "out":
            cli.add_output_options(parser, default, text, resume=True)
        else:
            kind = CHECKS.get(f.name, cli.finite_float if isinstance(default, float) else type(default))
            parser.add_argument(flag, type=kind, default=default, choices=choices.get(f.name), help=text)
    return parser


def parse_args(argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None) -> Args:
    """The CLI: one ``--flag`` per field of :class:`Args` (and ``--overwrite``, ``--resume``)."""
    parser = parser or build_parser()
    namespace = vars(parser.parse_args(argv))
    run = {k: namespace.pop(k) for k in ("overwrite", "resume")}
    args = Args(**namespace)
    args.net_arch = tuple(args.net_arch)
    args.__dict__.update(run)  # read by the output set, not part of the training's record
    if not NAME.match(args.name):
        parser.error(f"argument --name: {args.name!r} is not a plain file name (letters, digits, _ . -)")
    try:
        found = cli.choices_list(UNCERTAINTY_PRESETS, "uncertainty")(args.uncertainty)
        if len(found) > args.num_envs:
            raise argparse.ArgumentTypeError(
                f"{len(found)} levels for {args.num_envs} env copies (--num-envs)"
            )
    except argparse.ArgumentTypeError as error:
        parser.error(f"argument --uncertainty: {error}")
    try:
        epsilons = cli.numbers_list(cli.nonnegative_float)(args.tolerances)
    except argparse.ArgumentTypeError as error:
        parser.error(f"argument --tolerances: {error}")
    from risk_env.risk.severity import check_tolerance

    try:
        for eps in epsilons:
            check_tolerance(eps, args.severity, "argument --tolerances: value")
        check_tolerance(args.eval_epsilon, args.severity, "argument --eval-epsilon:")
    except ValueError as error:
        parser.error(str(error))
    if not args.conditioned and args.scene != "paper":
        parser.error("argument --no-conditioned: it sees one object only: train it on --scene paper")
    return args


def planned_timesteps(args: Args) -> int:
    """The env steps PPO will train: ``total_timesteps`` rounded up to whole rollouts.

    stable-baselines3 collects a full rollout (``n_steps`` steps of each of the ``num_envs``
    copies) before it checks the budget, so it trains a multiple of ``n_steps x num_envs``.
    """
    rollout = args.n_steps * args.num_envs
    return -(-args.total_timesteps // rollout) * rollout


def train(args: Args, shown: Path | None = None) -> dict[str, Any]:
    """Train, save ``OUT/NAME.zip`` and ``OUT/NAME.json``; returns the metadata written. ``shown``:
    the folder the files end up in (recorded in the metadata; default ``args.out``)."""
    shown = args.out if shown is None else shown
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
        "args": {k: (str(v) if isinstance(v, Path) else v) for k, v in dataclasses.asdict(args).items()}
        | {"out": str(shown)},
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
        f" including updates); saved {shown / (args.name + '.zip')}"
    )
    return metadata


def train_seeds(args: Args, store: Any = None, shown: Path | None = None) -> dict[str, Any]:
    """Train ``args.seeds`` seeds, score each (:func:`benchmarks.ppo_eval.evaluate`), write the
    table ``OUT/NAME_seeds.md`` (and ``.json``) and copy the best seed to ``OUT/NAME.zip``/``.json``.
    ``store`` (:class:`benchmarks.output.ChunkStore`): each finished seed is kept there, and a seed
    found there is not trained again (``--resume``); ``shown``: as for :func:`train`."""
    import shutil

    from benchmarks.ppo_eval import best_seed, evaluate, seed_table

    shown = args.out if shown is None else shown
    results: dict[int, dict[str, float]] = {}
    folder = args.out / f"{args.name}_seeds"
    walls: dict[int, dict[str, float]] = {}
    for seed in range(args.seed, args.seed + args.seeds):
        key = f"seed{seed}"
        if store is not None and key in store:
            walls[seed], results[seed] = store.get(key)
            print(f"seed {seed}: kept from the interrupted run")
            continue
        one = dataclasses.replace(args, seed=seed, seeds=1, name=f"{args.name}_seed{seed}", out=folder)
        meta = train(one, shown / folder.name)
        walls[seed] = {"wall_time_s": meta["wall_time_s"], "steps_per_s": meta["steps_per_s"]}
        results[seed] = evaluate(
            folder / f"{one.name}.zip", args.eval_episodes, "medium", args.eval_epsilon, seed=0
        )
        if store is not None:
            store.put(key, (walls[seed], results[seed]))
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


def files(name: str) -> tuple[str, ...]:
    """The files (and folders) a run named ``name`` writes in ``--out``."""
    return tuple(f"{name}{suffix}" for suffix in (".zip", ".json", "_seeds.md", "_seeds.json", "_seeds",
                                                   "_checkpoints", "_logs"))  # fmt: skip


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Parse the command line, say how many env steps will be trained, and train (every seed)."""
    parser = build_parser()
    args = parse_args(argv, parser)
    out = cli.open_output(parser, args, args.name, files(args.name), argv)
    planned = planned_timesteps(args)
    if planned != args.total_timesteps:
        print(
            f"--total-timesteps {args.total_timesteps} rounded up to {planned}: PPO trains whole rollouts"
            f" of n_steps x num_envs = {args.n_steps} x {args.num_envs} = {args.n_steps * args.num_envs}"
            " env steps"
        )
    with out:
        run = dataclasses.replace(args, out=out.dir)
        return train(run, args.out) if args.seeds == 1 else train_seeds(run, out.store, args.out)


if __name__ == "__main__":
    main()
