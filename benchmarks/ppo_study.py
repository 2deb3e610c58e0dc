"""The study behind the PPO reward weights and the prediction features: short training runs of a
few settings, each scored on sampled motion at medium uncertainty, epsilon 0 and 2500 J.

    python -m benchmarks.ppo_study --total-timesteps 1500000 --out docs/results/ppo_study

Writes ``OUT/study.md`` (one row per setting and epsilon) and ``OUT/study.json``; the models go to
``OUT/models`` (not committed).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from benchmarks import cli

SETTINGS: dict[str, list[str]] = {
    "path error only, penalty 300": ["--w-progress", "0", "--w-goal", "0", "--no-prediction"],
    "progress 1, goal 10, penalty 300": ["--w-progress", "1", "--w-goal", "10", "--no-prediction"],
    "progress 2, goal 30, penalty 300": ["--w-progress", "2", "--w-goal", "30", "--no-prediction"],
    "progress 1, goal 10, penalty 300, prediction": ["--w-progress", "1", "--w-goal", "10", "--prediction"],
    "progress 1, goal 10, Lagrangian from 300": [
        "--w-progress",
        "1",
        "--w-goal",
        "10",
        "--no-prediction",
        "--lagrangian",
    ],
}
"""Setting name -> the train_ppo flags that make it (beside --total-timesteps and --seed); every
setting trains with --risk-weight 300 and the other defaults of train_ppo."""
EPSILONS = (0.0, 2500.0)
"""epsilon of the evaluations [J]."""


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.ppo_study``."""
    p = cli.parser("ppo_study", __doc__)
    p.add_argument("--total-timesteps", type=int, default=1_500_000, help="env steps per setting")
    p.add_argument("--episodes", type=int, default=256, help="evaluation episodes per epsilon")
    p.add_argument("--seed", type=int, default=0, help="training seed of every setting")
    p.add_argument("--out", type=Path, default=Path("results/ppo_study"), help="output folder")
    return p


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    """Train and score every setting of :data:`SETTINGS` (``--only``: a comma list of them)."""
    from benchmarks import train_ppo
    from benchmarks.ppo_eval import evaluate

    args = build_parser().parse_args(argv)
    rows: list[dict[str, Any]] = []
    for i, (name, flags) in enumerate(SETTINGS.items()):
        model = f"setting{i}"
        argv_one = [
            *flags,
            "--risk-weight",
            "300",
            "--total-timesteps",
            str(args.total_timesteps),
            "--seed",
            str(args.seed),
        ]
        argv_one += ["--out", str(args.out / "models"), "--name", model, "--no-progress-bar"]
        argv_one += ["--checkpoint-every", "0"]
        t0 = time.perf_counter()
        meta = train_ppo.main(argv_one)
        for eps in EPSILONS:
            scores = evaluate(args.out / "models" / f"{model}.zip", args.episodes, "medium", eps)
            rows.append(
                {
                    "setting": name,
                    "flags": " ".join(flags),
                    "epsilon": eps,
                    **scores,
                    "train_s": meta["wall_time_s"],
                    "steps_per_s": meta["steps_per_s"],
                }
            )
        print(f"{name}: {time.perf_counter() - t0:.0f} s")
        write(rows, args)
    return rows


def write(rows: list[dict[str, Any]], args: argparse.Namespace) -> None:
    """``study.md`` and ``study.json`` of the rows so far."""
    args.out.mkdir(parents=True, exist_ok=True)
    lines = [
        f"PPO study: {args.total_timesteps:,} env steps per setting (seed {args.seed}); scored on"
        f" {args.episodes} episodes each (sampled motion, medium uncertainty)",
        "",
        "| setting | eps [J] | e_acc | collisions | goal | episode cost | d_min [m] | train [s] | steps/s |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        lines.append(
            f"| {r['setting']} | {r['epsilon']:g} | {r['e_acc']:.1f} | {100 * r['collision_rate']:.1f}%"
            f" | {100 * r['goal_rate']:.1f}% | {r['episode_cost']:.3g} | {r['d_min']:.1f}"
            f" | {r['train_s']:.0f} | {r['steps_per_s']:,.0f} |"
        )
    (args.out / "study.md").write_text("\n".join(lines) + "\n")
    (args.out / "study.json").write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
