"""Risk under real uncertainty: agents over many seeded episodes with sampled object motion.

    python -m benchmarks.sampled                       # the headline table (200 episodes each)
    python -m benchmarks.sampled --episodes 20 --agents smpc:exact --tolerances 0,2500
    python -m benchmarks.sampled --severities paper,probability,injury \
        --tolerances paper=0,1000,2500 --tolerances probability=0,0.01 --tolerances injury=0,0.005
    python -m benchmarks.sampled --scene two_crossing --out results/two_crossing

With ``object_motion="sampled"`` the object's true next position and speed are drawn from the
very prediction model the agents plan with, so the env's per-step risk R_{k+1|k} is the exact
expected harm of the next step. The question: does the tolerance epsilon bound what happens?

Tolerances are taken in each severity's own unit (J, probability, injuries; the ``unit`` column),
and a value that cannot be one (a probability above 1, more than 2 injuries per step) is an error.
Reported per configuration: the collision rate per episode (Wilson 95% interval), mean and 95th
percentile of the per-step risk, the share of steps whose risk exceeded epsilon, the realised
harm per step (mean of I_C s over the steps that happened: it should match the mean risk), the
episode's summed risk (``info["episode_risk"]``, mean and max over episodes), the realised harm
per episode (it should match the mean episode risk), e_acc, d_min and the goal rate.

``--budgets`` adds a row per episode risk budget B (in the severity's own unit, checked as the
tolerances are) for each SMPC agent, built with ``risk_budget=B`` and no per-step bound
(:mod:`benchmarks.budget_rows`, written to ``budget.csv`` and a second table of ``sampled.md``).
With ``--budgets`` and no ``--tolerances`` the agents that take no budget (RMPC, PPO) run at
epsilon = 0 and the SMPC agents run the budget rows only.

    python -m benchmarks.sampled --agents rmpc:worst_case,smpc:exact --severities probability \
        --budgets 0.05,0.01 --episodes 1000 --out docs/results/budget
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
from benchmarks.budget_rows import BUDGET_COLUMNS, markdown_budget, summarise_budget
from benchmarks.rollout import AGENTS, available_agents, build_agent, rollout
from benchmarks.sweep import run_sweep
from risk_env.scenario.scenario import SCENE_NAMES, SEVERITY_NAMES, UNCERTAINTY_PRESETS

COLUMNS = (
    "agent",
    "scene",
    "severity",
    "unit",
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
    "episode_risk_mean",
    "episode_risk_max",
    "harm_per_episode",
    "e_acc_mean",
    "d_min_mean",
    "d_min_min",
    "goal_rate",
    "failed_solves",
    "solve_ms_median",
    "fallback_soft",
    "fallback_manoeuvre",
    "fallbacks_per_episode",
    "episodes_with_fallback",
)


@dataclass(frozen=True)
class Job:
    agent: str
    severity: str
    uncertainty: str
    epsilon: float
    seeds: tuple[int, ...]
    scene: str = "paper"
    """Which road users cross (:data:`risk_env.SCENE_NAMES`)."""
    budget: float | None = None
    """An episode risk budget B: the agent gets ``risk_budget=B`` and no per-step bound."""
    max_solve_time: float | None = None
    """The MPC's wall-time cap per step [s] (None: its default, 20 % of T; ``math.inf``: none)."""


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
    from risk_env.models.ops import NUMPY
    from risk_env.risk.severity import make_severity

    env = gym.make(
        "RiskCrossing-v0",
        uncertainty=job.uncertainty,
        risk_tolerance=job.epsilon,
        severity=job.severity,
        object_motion="sampled",
        scene=job.scene,
    )
    options: dict[str, Any] = {}
    if job.budget is not None:
        options.update(risk_budget=job.budget, risk_tolerance=math.inf)
    if job.max_solve_time is not None and not job.agent.startswith("ppo"):
        options["max_solve_time"] = job.max_solve_time
    agent = build_agent(*AGENTS[job.agent], env, **options)
    scenario = env.unwrapped.scenario
    severities = [make_severity(scenario.for_object(i)) for i in range(len(scenario.objects))]
    radii = scenario.collision_distances
    out = []
    for seed in job.seeds:
        rec = rollout(agent, env, seed=seed)
        # realised harm of each step: sum_i I_C,i s_i at the state reached (only the last step can
        # collide), each object with its own mass and radius
        harm = np.zeros(rec.steps)
        if rec.collision:
            e = rec.ego[-1]
            for o, r, severity, there in zip(rec.objects[-1], radii, severities, rec.info["present"]):
                if there and np.hypot(e[0] - o[0], e[1] - o[1]) <= r:
                    harm[-1] += float(severity.value(e[3], e[2], o[3], o[2], NUMPY))
        out.append(
            {
                "collision": rec.collision,
                "success": rec.success,
                "risk": rec.risk,
                "harm": harm,
                "episode_risk": float(rec.info["episode_risk"]),
                "violations": int(np.sum(rec.risk > job.epsilon * (1 + 1e-6) + 1e-9)),
                "e_acc": rec.e_acc,
                "d_min": rec.d_min,
                "failures": rec.failures,
                "soft": rec.fallbacks("soft"),
                "manoeuvre": rec.fallbacks("manoeuvre"),
                "solve_ms": 1e3 * rec.solve_time,
            }
        )
    env.close()
    return out


def _sig(x: float, digits: int = 4) -> float:
    """``x`` rounded to ``digits`` significant digits (risks span J to 1e-6 injuries)."""
    return float(f"{x:.{digits}g}")


def summarise(job: Job, episodes: list[dict[str, Any]]) -> dict[str, Any]:
    from risk_env.risk.severity import make_severity
    from risk_env.scenario.scenario import Scenario

    n = len(episodes)
    collisions = sum(e["collision"] for e in episodes)
    lo, hi = wilson(collisions, n)
    risk = np.concatenate([e["risk"] for e in episodes])
    harm = np.concatenate([e["harm"] for e in episodes])
    episode_risk = np.array([e["episode_risk"] for e in episodes])
    solve = np.concatenate([e["solve_ms"] for e in episodes])
    return {
        "agent": job.agent,
        "scene": job.scene,
        "severity": job.severity,
        "unit": make_severity(Scenario(severity=job.severity)).unit,
        "uncertainty": job.uncertainty,
        "epsilon": job.epsilon,
        "episodes": n,
        "collision_rate": round(collisions / n, 4),
        "collision_ci_low": round(lo, 4),
        "collision_ci_high": round(hi, 4),
        "risk_mean": _sig(risk.mean()),
        "risk_p95": _sig(np.percentile(risk, 95)),
        "violation_rate": round(sum(e["violations"] for e in episodes) / len(risk), 4),
        "harm_per_step": _sig(harm.mean()),
        "episode_risk_mean": _sig(episode_risk.mean()),
        "episode_risk_max": _sig(episode_risk.max()),
        "harm_per_episode": _sig(harm.sum() / n),
        "e_acc_mean": round(float(np.mean([e["e_acc"] for e in episodes])), 2),
        "d_min_mean": round(float(np.mean([e["d_min"] for e in episodes])), 2),
        "d_min_min": round(float(np.min([e["d_min"] for e in episodes])), 2),
        "goal_rate": round(sum(e["success"] for e in episodes) / n, 4),
        "failed_solves": int(sum(e["failures"] for e in episodes)),
        "solve_ms_median": round(float(np.median(solve)), 2),
        "fallback_soft": int(sum(e["soft"] for e in episodes)),
        "fallback_manoeuvre": int(sum(e["manoeuvre"] for e in episodes)),
        "fallbacks_per_episode": round(sum(e["failures"] for e in episodes) / n, 3),
        "episodes_with_fallback": int(sum(e["failures"] > 0 for e in episodes)),
    }


def markdown(rows: list[dict[str, Any]]) -> str:
    scenes = sorted({r.get("scene", "paper") for r in rows})
    lines = [
        "# Sampled object motion: does epsilon bound what happens?",
        "",
        *([f"Scene {', '.join(scenes)} (risk_env.scenario.scenes).", ""] if scenes != ["paper"] else []),
        "Risks, eps and harm in the severity's own unit (given with eps). Harm/step = mean realised",
        "I_C s per step; with calibrated risk it matches Risk mean (both are per-step expected harm).",
        "Episode risk = info['episode_risk'], the summed risk of an episode (mean and max over",
        "episodes); harm/episode is its realised counterpart. Collisions: share of episodes.",
        "",
        "| agent | severity | unc. | eps | episodes | collisions/episode [95% CI] | risk mean | risk p95 |"
        " steps > eps | harm/step | episode risk mean (max) | harm/episode | e_acc | d_min mean (min) |"
        " goal | fallbacks (soft / manoeuvre) | fallbacks/episode (episodes with any) |",
        "|" + " --- |" * 17,
    ]
    for r in rows:
        lines.append(
            f"| {r['agent']} | {r['severity']} | {r['uncertainty']} | {r['epsilon']:g} {r['unit']} | "
            f"{r['episodes']} | {100 * r['collision_rate']:.1f}% "
            f"[{100 * r['collision_ci_low']:.1f}, {100 * r['collision_ci_high']:.1f}] | "
            f"{r['risk_mean']:.3g} | {r['risk_p95']:.3g} | {100 * r['violation_rate']:.1f}% | "
            f"{r['harm_per_step']:.3g} | {r['episode_risk_mean']:.3g} ({r['episode_risk_max']:.3g}) | "
            f"{r['harm_per_episode']:.3g} | {r['e_acc_mean']:.1f} | "
            f"{r['d_min_mean']:.1f} ({r['d_min_min']:.1f}) | "
            f"{100 * r['goal_rate']:.0f}% | "
            f"{r['failed_solves']} ({r['fallback_soft']} / {r['fallback_manoeuvre']}) | "
            f"{r['fallbacks_per_episode']:.2f} ({r['episodes_with_fallback']}) |"
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
    p.add_argument("--severities", default="paper,plastic", help=f"comma list of {', '.join(SEVERITY_NAMES)}")
    p.add_argument("--uncertainty", default="medium", help="comma list of low, medium, high")
    p.add_argument(
        "--tolerances",
        action="append",
        metavar="[SEVERITY=]EPS,...",
        help="comma list of epsilon in the severity's own unit (default 0,1000,2500); repeat as"
        " SEVERITY=EPS,... to give a severity its own list",
    )
    p.add_argument(
        "--budgets",
        action="append",
        metavar="[SEVERITY=]B,...",
        help="comma list of episode risk budgets B in the severity's own unit: a row per budget for"
        " each SMPC agent (risk_budget=B, no per-step bound); repeat as SEVERITY=B,... (default: none)",
    )
    p.add_argument(
        "--scene",
        default="paper",
        choices=SCENE_NAMES,
        help="which road users cross (risk_env.scenario.scenes; default: the paper's one object)",
    )
    p.add_argument(
        "--max-solve-time",
        type=float,
        default=math.inf,
        help="the MPC agents' wall-time cap per step [s]; inf: none, so that results do not depend on"
        " the machine's load; 0.1: the agents' own default, 20%% of T",
    )
    p.add_argument("--episodes", type=int, default=200, help="seeded episodes per configuration")
    p.add_argument("--chunk", type=int, default=25, help="episodes per job (one agent build per job)")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("results"),
        help="output folder for sampled.csv and sampled.md; the committed ones are in docs/results",
    )
    cli.add_sweep_options(p)
    return p


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = build_parser()
    args = p.parse_args(argv)
    if args.agents is None:
        args.agents = [a for a in available_agents(args.scene) if a != "rmpc:grid"]
    else:
        args.agents = [a for a in args.agents.split(",") if a]
    if bad := [a for a in args.agents if a not in AGENTS]:
        p.error(f"unknown agent(s) {bad}; expected from {list(AGENTS)}")
    args.severities = [s for s in args.severities.split(",") if s]
    if bad := [s for s in args.severities if s not in SEVERITY_NAMES]:
        p.error(f"unknown severity {bad}; expected from {list(SEVERITY_NAMES)}")
    args.uncertainty = [u for u in args.uncertainty.split(",") if u]
    if bad := [u for u in args.uncertainty if u not in UNCERTAINTY_PRESETS]:
        p.error(f"unknown uncertainty {bad}; expected from {list(UNCERTAINTY_PRESETS)}")
    only_budgets = bool(args.budgets) and not args.tolerances
    try:
        args.tolerances = parse_tolerances(
            args.tolerances or (["0"] if only_budgets else ["0,1000,2500"]), args.severities
        )
        args.budgets = parse_tolerances(args.budgets, args.severities, "budget") if args.budgets else {}
    except ValueError as error:
        p.error(str(error))
    args.only_budgets = only_budgets
    if args.episodes < 1 or args.chunk < 1:
        p.error("--episodes and --chunk must be >= 1")
    return args


def parse_tolerances(
    groups: list[str], severities: list[str], what: str = "tolerance"
) -> dict[str, list[float]]:
    """``--tolerances`` (``what="budget"``: ``--budgets``) values -> epsilon (B) per severity, each
    in that severity's own unit.

    A group ``"A,B"`` applies to every severity without a group of its own ``"NAME=A,B"``. Raises
    ``ValueError`` naming a value that is not a number, or not one of its severity's unit
    (:func:`risk_env.risk.severity.check_tolerance`), and a severity left without tolerances.
    """
    from risk_env.risk.severity import check_tolerance

    common: list[float] | None = None
    own: dict[str, list[float]] = {}
    for group in groups:
        name, sep, values = group.rpartition("=")
        name = name.strip()
        flag = f"--{what}s"
        if sep and name not in severities:
            raise ValueError(
                f"{flag} {group!r} names severity {name!r}, not one of --severities {severities}"
            )
        try:
            numbers = [float(t) for t in values.split(",") if t.strip()]
        except ValueError:
            raise ValueError(f"{flag} {group!r}: expected numbers separated by commas") from None
        if sep:
            own[name] = numbers
        else:
            common = numbers
    out = {}
    for severity in severities:
        chosen = own.get(severity, common)
        if not chosen:
            raise ValueError(f"no {what}s for severity {severity!r}: pass --{what}s {severity}=VALUE,...")
        label = f"--{what}s value for severity {severity!r}"
        out[severity] = [check_tolerance(e, severity, label) for e in chosen]
    return out


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    args = parse_args(argv)
    smpc = [a for a in args.agents if AGENTS[a][0] == "SMPC"]
    configs = [
        (a, s, u, e, None)
        for a in args.agents
        if not (args.only_budgets and a in smpc)
        for s in args.severities
        for u in args.uncertainty
        for e in args.tolerances[s]
    ]
    configs += [
        (a, s, u, b, b)
        for a in smpc
        for s in args.severities
        for u in args.uncertainty
        for b in args.budgets.get(s, [])
    ]
    jobs = [
        Job(
            a,
            s,
            u,
            e,
            tuple(range(start, min(start + args.chunk, args.episodes))),
            args.scene,
            b,
            args.max_solve_time,
        )
        for (a, s, u, e, b) in configs
        for start in range(0, args.episodes, args.chunk)
    ]
    t0 = time.perf_counter()
    results = run_sweep(run_job, jobs, args.workers, args.ray, desc="episode chunks")
    by_config: dict[tuple, list[dict[str, Any]]] = {}
    for job, episodes in zip(jobs, results):
        key = (job.agent, job.severity, job.uncertainty, job.epsilon, job.budget)
        by_config.setdefault(key, []).extend(episodes)
    rows, budget_rows = [], []
    for (a, s, u, e, b), eps in by_config.items():
        row = summarise(Job(a, s, u, e, (), args.scene), eps)
        if b is None:
            rows.append(row)
        else:
            budget_rows.append(summarise_budget(row, b, eps))
    args.out.mkdir(parents=True, exist_ok=True)
    if budget_rows:
        with (args.out / "budget.csv").open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=BUDGET_COLUMNS)
            writer.writeheader()
            writer.writerows(budget_rows)
    with (args.out / "sampled.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    text = (
        markdown(rows)
        + (f"\n{markdown_budget(budget_rows)}" if budget_rows else "")
        + f"\nWall time: {time.perf_counter() - t0:.0f} s for {len(configs)} configurations.\n"
    )
    (args.out / "sampled.md").write_text(text)
    print(text)
    print(f"Wrote:\n  {args.out / 'sampled.csv'}\n  {args.out / 'sampled.md'}")
    return rows + budget_rows


if __name__ == "__main__":
    main()
