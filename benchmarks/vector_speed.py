"""Throughput of the vectorised ``RiskCrossing-v0``: env steps per second by vectorisation mode.

    python -m benchmarks.vector_speed                      # 64 copies, the three modes, exact risk
    python -m benchmarks.vector_speed --num-envs 1 8 64 --out docs/results

Random actions (the same for every mode) drive the copies, with seeded variations of the
scenario (``randomize=True``) so that the batch holds states near and far from the object.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import risk_env
from benchmarks import cli

MODES = ("vector_entry_point", "sync", "async")


def throughput(mode: str, num_envs: int, steps: int, repeats: int, **env_kwargs) -> float:
    """Best of ``repeats`` runs of ``steps`` batch steps: env steps per second (copies x steps / s)."""
    env = gym.make_vec(risk_env.ENV_ID, num_envs=num_envs, vectorization_mode=mode, **env_kwargs)
    space = env.unwrapped.single_action_space
    rng = np.random.default_rng(0)
    actions = rng.uniform(space.low, space.high, size=(steps, num_envs, 2)).astype(np.float32)
    best = np.inf
    for _ in range(repeats):
        env.reset(seed=0)
        start = time.perf_counter()
        for action in actions:
            env.step(action)
        best = min(best, time.perf_counter() - start)
    env.close()
    return steps * num_envs / best


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.vector_speed``."""
    parser = cli.parser("vector_speed", __doc__)
    parser.add_argument("--num-envs", type=int, nargs="+", default=[64], help="batch sizes (copies) to time")
    parser.add_argument(
        "--modes",
        nargs="+",
        choices=MODES,
        default=list(MODES),
        metavar="MODE",
        help=f"vectorisation modes, of {', '.join(MODES)}: the batched numpy env, or Gymnasium's"
        " vectors of single envs",
    )
    parser.add_argument(
        "--estimators",
        nargs="+",
        choices=risk_env.ESTIMATOR_NAMES,
        default=["exact"],
        metavar="ESTIMATOR",
        help=f"risk estimators, of {', '.join(risk_env.ESTIMATOR_NAMES)}",
    )
    parser.add_argument(
        "--object-motion", choices=risk_env.OBJECT_MOTIONS, default="sampled", help="how the object moves"
    )
    parser.add_argument("--steps", type=int, default=200, help="batch steps per run")
    parser.add_argument("--repeats", type=int, default=3, help="runs per row (the best is kept)")
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="also write the table to OUT/vector_speed.txt (default: print only; the committed one"
        " is in docs/results)",
    )
    return parser


def main(argv: list[str] | None = None) -> str:
    args = build_parser().parse_args(argv)

    lines = [
        f"RiskCrossing-v0 vectorised throughput (randomize=True, object_motion={args.object_motion},"
        f" {args.steps} batch steps, best of {args.repeats})",
        f"{'mode':>20} {'estimator':>12} {'copies':>7} {'env steps/s':>12} {'us/step':>9}",
    ]
    print("\n".join(lines), flush=True)
    for estimator in args.estimators:
        for num_envs in args.num_envs:
            for mode in args.modes:
                rate = throughput(
                    mode,
                    num_envs,
                    args.steps,
                    args.repeats,
                    risk_estimator=estimator,
                    randomize=True,
                    object_motion=args.object_motion,
                )
                line = f"{mode:>20} {estimator:>12} {num_envs:>7} {rate:>12,.0f} {1e6 / rate:>9.1f}"
                print(line, flush=True)
                lines.append(line)
    text = "\n".join(lines) + "\n"
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "vector_speed.txt").write_text(text)
    return text


if __name__ == "__main__":
    main()
