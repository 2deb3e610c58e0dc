"""Risk under real uncertainty: agents over many seeded episodes with sampled object motion.

    python -m benchmarks.sampled                       # the headline table (200 episodes each)
    python -m benchmarks.sampled --episodes 20 --agents smpc:exact --tolerances 0,2500

With ``object_motion="sampled"`` the object's true next position and speed are drawn from the
very prediction model the agents plan with, so the env's per-step risk R_{k+1|k} is the exact
expected harm of the next step. The question: does the tolerance epsilon bound what happens?
Reported per configuration: collision rate (Wilson 95% interval), mean and 95th percentile of the
per-step risk, the share of steps whose risk exceeded epsilon, the realised harm per step (mean of
I_C s over the steps that happened: it should match the mean risk), e_acc and d_min.
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cli
from benchmarks.rollout import AGENTS, available_agents, build_agent, rollout
from benchmarks.sweep import run_sweep

COLUMNS = (
    "agent",
    "severity",
    "uncertainty",
    "epsilon",
    "episodes",
    "collision_rate",
    "collision_ci_low",
    "collision_ci_high",
    "risk_mean",
    "risk_p95",
    "violation_rate",
    "harm_per_step",
    "e_acc_mean",
    "d_min_mean",
    "d_min_min",
    "goal_rate",
    "failed_solves",
    "solve_ms_median",
)


@dataclass(frozen=True)
class Job:
    agent: str
    severity: str
    uncertainty: str
    epsilon: float
    seeds: tuple[int, ...]


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion."""
    if n == 0:
        return (float("nan"), float("nan"))
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def run_job(job: Job) -> list[dict[str, Any]]:
    """Episodes of one configuration (the agent is built once and reset per episode)."""
    import gymnasium as gym

    import risk_env  # noqa: F401
    from risk_env.ops import NUMPY
    from risk_env.severity import make_severity

    env = gym.make(
        "RiskCrossing-v0",
        uncertainty=job.uncertainty,
        risk_tolerance=job.epsilon,
        severity=job.severity,
        object_motion="sampled",
    )
    agent = build_agent(*AGENTS[job.agent], env)
    severity = make_severity(env.unwrapped.scenario)
    out = []
    for seed in job.seeds:
        rec = rollout(agent, env, seed=seed)
        # realised harm of each step: I_C s at the state reached (only the last step can collide)
        harm = np.zeros(rec.steps)
        if rec.collision:
            e, o = rec.ego[-1], rec.object[-1]
            harm[-1] = float(severity.value(e[3], e[2], o[3], o[2], NUMPY))
        out.append(
            {
                "collision": rec.collision,
                "success": rec.success,
                "risk": rec.risk,
                "harm": harm,
                "violations": int(np.sum(rec.risk > job.epsilon * (1 + 1e-6) + 1e-9)),
                "e_acc": rec.e_acc,
                "d_min": rec.d_min,
                "failures": rec.failures,
                "solve_ms": 1e3 * rec.solve_time,
            }
        )
    env.close()
    return out


def summarise(job: Job, episodes: list[dict[str, Any]]) -> dict[str, Any]:
    n = len(episodes)
    collisions = sum(e["collision"] for e in episodes)
    lo, hi = wilson(collisions, n)
    risk = np.concatenate([e["risk"] for e in episodes])
    harm = np.concatenate([e["harm"] for e in episodes])
    solve = np.concatenate([e["solve_ms"] for e in episodes])
    return {
        "agent": job.agent,
        "severity": job.severity,
        "uncertainty": job.uncertainty,
        "epsilon": job.epsilon,
        "episodes": n,
        "collision_rate": round(collisions / n, 4),
        "collision_ci_low": round(lo, 4),
        "collision_ci_high": round(hi, 4),
        "risk_mean": round(float(risk.mean()), 3),
        "risk_p95": round(float(np.percentile(risk, 95)), 3),
        "violation_rate": round(sum(e["violations"] for e in episodes) / len(risk), 4),
        "harm_per_step": round(float(harm.mean()), 3),
        "e_acc_mean": round(float(np.mean([e["e_acc"] for e in episodes])), 2),
        "d_min_mean": round(float(np.mean([e["d_min"] for e in episodes])), 2),
        "d_min_min": round(float(np.min([e["d_min"] for e in episodes])), 2),
        "goal_rate": round(sum(e["success"] for e in episodes) / n, 4),
        "failed_solves": int(sum(e["failures"] for e in episodes)),
        "solve_ms_median": round(float(np.median(solve)), 2),
    }


def markdown(rows: list[dict[str, Any]]) -> str:
    lines = [
        "# Sampled object motion: does epsilon bound what happens?",
        "",
        "Risk in the severity's unit (J, or probability). Harm/step = mean realised I_C s per step;",
        "with calibrated risk it matches Risk mean (both are per-step expected harm).",
        "",
        "| agent | severity | unc. | eps | episodes | collisions [95% CI] | risk mean | risk p95 |"
        " steps > eps | harm/step | e_acc | d_min mean (min) | goal | failed |",
        "|" + " --- |" * 14,
    ]
    for r in rows:
        lines.append(
            f"| {r['agent']} | {r['severity']} | {r['uncertainty']} | {r['epsilon']:g} | {r['episodes']} | "
            f"{100 * r['collision_rate']:.1f}% "
            f"[{100 * r['collision_ci_low']:.1f}, {100 * r['collision_ci_high']:.1f}] | "
            f"{r['risk_mean']:.3g} | {r['risk_p95']:.3g} | {100 * r['violation_rate']:.1f}% | "
            f"{r['harm_per_step']:.3g} | {r['e_acc_mean']:.1f} | "
            f"{r['d_min_mean']:.1f} ({r['d_min_min']:.1f}) | "
            f"{100 * r['goal_rate']:.0f}% | {r['failed_solves']} |"
        )
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.sampled``."""
    p = cli.parser("sampled", __doc__)
    p.add_argument(
        "--agents",
        default=None,
        help=f"comma list from {', '.join(AGENTS)} (default: all but the grid RMPC; PPO with the rl extra)",
    )
    p.add_argument("--severities", default="paper,plastic", help="comma list of paper, plastic, probability")
    p.add_argument("--uncertainty", default="medium", help="comma list of low, medium, high")
    p.add_argument(
        "--tolerances",
        default="0,1000,2500",
        help="comma list of epsilon [J]; with the probability severity each is divided by 10,000",
    )
    p.add_argument("--episodes", type=int, default=200, help="seeded episodes per configuration")
    p.add_argument("--chunk", type=int, default=25, help="episodes per job (one agent build per job)")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("results"),
        help="output folder for sampled.csv and sampled.md; the committed ones are in docs/results",
    )
    p.add_argument("--workers", type=int, default=None, help="processes (default: one per core)")
    p.add_argument(
        "--ray",
        nargs="?",
        const="",
        default=False,
        metavar="ADDRESS",
        help="run on Ray: a local instance without ADDRESS, else the cluster at ADDRESS"
        " (default: a process pool)",
    )
    return p


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = build_parser()
    args = p.parse_args(argv)
    if args.agents is None:
        args.agents = [a for a in available_agents() if a != "rmpc:grid"]
    else:
        args.agents = [a for a in args.agents.split(",") if a]
    if bad := [a for a in args.agents if a not in AGENTS]:
        p.error(f"unknown agent(s) {bad}; expected from {list(AGENTS)}")
    args.severities = [s for s in args.severities.split(",") if s]
    if bad := [s for s in args.severities if s not in ("paper", "plastic", "probability")]:
        p.error(f"unknown severity {bad}")
    args.uncertainty = [u for u in args.uncertainty.split(",") if u]
    if bad := [u for u in args.uncertainty if u not in ("low", "medium", "high")]:
        p.error(f"unknown uncertainty {bad}")
    args.tolerances = [float(t) for t in args.tolerances.split(",") if t]
    if args.episodes < 1 or args.chunk < 1:
        p.error("--episodes and --chunk must be >= 1")
    return args


def scaled_tolerance(eps: float, severity: str) -> float:
    """The probability severity is dimensionless: map the J tolerances onto [0, 1] (2500 J -> 0.25)."""
    return eps / 10_000.0 if severity == "probability" else eps


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    args = parse_args(argv)
    configs = [
        (a, s, u, scaled_tolerance(e, s))
        for a in args.agents
        for s in args.severities
        for u in args.uncertainty
        for e in args.tolerances
    ]
    jobs = [
        Job(a, s, u, e, tuple(range(start, min(start + args.chunk, args.episodes))))
        for (a, s, u, e) in configs
        for start in range(0, args.episodes, args.chunk)
    ]
    t0 = time.perf_counter()
    results = run_sweep(run_job, jobs, args.workers, args.ray, desc="episode chunks")
    by_config: dict[tuple, list[dict[str, Any]]] = {}
    for job, episodes in zip(jobs, results):
        by_config.setdefault((job.agent, job.severity, job.uncertainty, job.epsilon), []).extend(episodes)
    rows = [summarise(Job(*cfg, ()), eps) for cfg, eps in by_config.items()]
    args.out.mkdir(parents=True, exist_ok=True)
    with (args.out / "sampled.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    text = (
        markdown(rows) + f"\nWall time: {time.perf_counter() - t0:.0f} s for {len(configs)} configurations.\n"
    )
    (args.out / "sampled.md").write_text(text)
    print(text)
    print(f"Wrote:\n  {args.out / 'sampled.csv'}\n  {args.out / 'sampled.md'}")
    return rows


if __name__ == "__main__":
    main()
