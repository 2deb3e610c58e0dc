"""The study behind the PPO reward weights and the prediction features: short training runs of a
few settings, each scored on sampled motion at medium uncertainty, epsilon 0 and 2500 J.

    python -m benchmarks.ppo_study --total-timesteps 1500000 --out docs/results/ppo_study

Writes ``OUT/study.md`` (one row per setting and epsilon) and ``OUT/study.json``; the models go to
``OUT/models`` (not committed). One output set (:mod:`benchmarks.output`): ``--resume`` keeps the
settings an interrupted run finished.
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
    p.add_argument(
        "--total-timesteps", type=cli.positive_int, default=1_500_000, help="env steps per setting"
    )
    p.add_argument("--episodes", type=cli.positive_int, default=256, help="evaluation episodes per epsilon")
    p.add_argument("--seed", type=cli.nonnegative_int, default=0, help="training seed of every setting")
    cli.add_output_options(p, Path("results/ppo_study"), "output folder", resume=True)
    return p


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    """Train and score every setting of :data:`SETTINGS`."""
    from benchmarks import train_ppo
    from benchmarks.ppo_eval import evaluate

    parser = build_parser()
    args = parser.parse_args(argv)
    out = cli.open_output(parser, args, "study", ("study.md", "study.json", "models"), argv)
    rows: list[dict[str, Any]] = []
    with out:
        for i, (name, flags) in enumerate(SETTINGS.items()):
            key = f"setting{i}"
            if key in out.store:
                rows += out.store.get(key)
                continue
            model = f"setting{i}"
            models = out.dir / "models"
            argv_one = [
                *flags,
                "--risk-weight",
                "300",
                "--total-timesteps",
                str(args.total_timesteps),
                "--seed",
                str(args.seed),
            ]
            argv_one += ["--out", str(models), "--name", model, "--no-progress-bar", "--overwrite"]
            argv_one += ["--checkpoint-every", "0"]
            t0 = time.perf_counter()
            meta = train_ppo.main(argv_one)
            found = []
            for eps in EPSILONS:
                scores = evaluate(models / f"{model}.zip", args.episodes, "medium", eps)
                found.append(
                    {
                        "setting": name,
                        "flags": " ".join(flags),
                        "epsilon": eps,
                        **scores,
                        "train_s": meta["wall_time_s"],
                        "steps_per_s": meta["steps_per_s"],
                    }
                )
            out.store.put(key, found)
            rows += found
            print(f"{name}: {time.perf_counter() - t0:.0f} s")
        write(rows, args, out.dir)
    return rows


def write(rows: list[dict[str, Any]], args: argparse.Namespace, folder: Path) -> None:
    """``study.md`` and ``study.json`` of the rows in ``folder``."""
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
    (folder / "study.md").write_text("\n".join(lines) + "\n")
    (folder / "study.json").write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
