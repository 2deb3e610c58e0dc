r"""The standing reliability benchmark: every MPC agent over a seeded family of random scenes.

    python -m benchmarks.stress            # 200 scenes x rmpc, smpc:paper:0, smpc:paper:1000
    python -m benchmarks.stress --scenes 20 --agents rmpc --out results/stress20
    python -m benchmarks.stress --family cap --scenes 500 --workers 2 --out docs/results/cap

The scenes (:mod:`benchmarks.scenes`): starts near the path; objects close by, crossing the path,
or never crossing it; every uncertainty level of Table I and an enlarged growth; $v_{ref}$ from 1 to
8 m/s; the paper's and sampled object motion. Per agent it reports collisions, split into
avoidable (some rate-limited open-loop manoeuvre from the start would have kept clear of the
object's true motion for the whole episode) and unavoidable; how often each fallback level of
the MPC acted (``"soft"``: the risk rows softened; ``"manoeuvre"``: the safest rate-limited
manoeuvre), as a share of all steps; solver calls that failed; and the step time (the whole
``predict``) at p50 / p95 / p99 / max.

Agents are named as in every command (:mod:`benchmarks.agent_names`); an SMPC without a tolerance
runs at $\epsilon = 0$ in the paper's severity (J). Writes ``stress.csv`` (one row per agent and
scene), ``stress_summary.csv`` and ``stress.md`` (the command that made them in its header) to
``--out``, as one output set (:mod:`benchmarks.output`; ``--resume`` goes on after an interruption).

``--family cap`` (:mod:`benchmarks.cap_family`): each scene with an agent of its own drawn over
severities, tolerances, episode budgets and risk weights, and every solver call checked against the
step's cap (iterations past the rung's limit, calls over twice the cap in wall and CPU time);
``--agents`` then names its groups; writes ``cap.csv``, ``cap_summary.csv`` and ``cap.md``.
"""

from __future__ import annotations

import argparse
import gc
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cap_family, cli
from benchmarks.agent_names import AgentName, parse_agent
from benchmarks.output import write_csv
from benchmarks.scenes import Scene, infeasible_step, make_scenes, object_truth, witness_clearance
from benchmarks.sweep import default_workers, run_sweep

DEFAULT_AGENTS = ("rmpc:worst_case", "smpc:exact:paper:0", "smpc:exact:paper:1000")
"""The agents of the standing benchmark (``smpc:monte_carlo:paper:1000`` too in the committed run)."""
FILES = ("stress.csv", "stress_summary.csv", "stress.md")
"""The files a run writes in ``--out``."""


def agent(name: str) -> AgentName:
    r"""The agent ``name`` (an SMPC without a tolerance: $\epsilon = 0$, the paper's severity)."""
    return parse_agent(name, ("rmpc", "smpc")).with_defaults("paper", 0.0)


EPISODE_COLUMNS = (
    "agent",
    "scene",
    "uncertainty",
    "kind",
    "motion",
    "v_ref",
    "epsilon",
    "steps",
    "collided",
    "avoidable",
    "witness_clearance",
    "d_min",
    "reached_goal",
    "fallback_soft",
    "fallback_manoeuvre",
    "penalty_steps",
    "infeasible_steps",
    "failed_calls",
    "overran_calls",
    "over_cap_steps",
    "capped_steps",
    "solve_ms_p50",
    "solve_ms_max",
)
SUMMARY_COLUMNS = (
    "agent",
    "scenes",
    "steps",
    "collisions",
    "avoidable",
    "unavoidable",
    "fallback_pct",
    "soft_pct",
    "manoeuvre_pct",
    "penalty_steps",
    "infeasible_pct",
    "failed_calls",
    "overran_calls",
    "over_cap_steps",
    "feasible_fallback_pct",
    "capped_steps",
    "solve_ms_p50",
    "solve_ms_p95",
    "solve_ms_p99",
    "solve_ms_max",
    "cpu_ms_max",
    "soft_violation_median",
)


@dataclass(frozen=True)
class Job:
    """One agent on one scene."""

    agent: str
    scene: Scene
    options: tuple[tuple[str, Any], ...] = ()


def run_job(job: Job) -> dict[str, Any]:
    """One episode: its CSV row, plus its per-step solve times ``"_times"`` [s]."""
    import gymnasium as gym

    import risk_env  # noqa: F401  (registers the env)
    from benchmarks.rollout import build, rollout

    name = agent(job.agent)
    epsilon = name.tolerance or 0.0
    scene = job.scene
    kwargs = scene.env_kwargs(epsilon)
    kwargs["scenario"] = kwargs["scenario"].replace(severity=name.severity or "paper")
    env = gym.make("RiskCrossing-v0", **kwargs)
    agent_ = build(name, env, seed=scene.index, **dict(job.options))
    gc.collect()  # the previous episode's agent (its reports hold it in a cycle) goes here, not in a step
    record = rollout(agent_, env, seed=scene.seed)
    env.close()
    truth = object_truth(scene)
    steps = record.steps
    if not np.allclose(record.object[:, :2], truth[: steps + 1], atol=1e-9):  # the replay is the env's
        raise RuntimeError(f"scene {scene.label}: the replayed object motion differs from the env's")
    clearance = witness_clearance(scene, truth)
    reports = [r for r in record.reports if r is not None]
    ms = 1e3 * record.solve_time
    return {
        "agent": job.agent,
        "scene": scene.index,
        "uncertainty": scene.uncertainty,
        "kind": scene.kind,
        "motion": scene.motion,
        "v_ref": dict(scene.overrides)["v_ref"],
        "epsilon": epsilon,
        "steps": steps,
        "collided": record.collision,
        "avoidable": record.collision and clearance > 0.0,
        "witness_clearance": round(clearance, 3),
        "d_min": round(record.d_min, 3),
        "reached_goal": record.success,
        "fallback_soft": record.fallbacks("soft"),
        "fallback_manoeuvre": record.fallbacks("manoeuvre"),
        "penalty_steps": int(sum(r.fallback is None and r.variant.endswith("_soft") for r in reports)),
        "infeasible_steps": infeasible_steps(scene, record, epsilon, agent_) if epsilon == 0.0 else "",
        "failed_calls": int(sum(getattr(r, "failed_calls", int(r.failed)) for r in reports)),
        "overran_calls": int(sum(getattr(r, "overran_calls", 0) for r in reports)),
        "over_cap_steps": int(np.sum(record.solve_time > agent_.max_solve_time)),
        "capped_steps": int(sum(bool(getattr(r, "capped", False)) for r in reports)),
        "solve_ms_p50": round(float(np.median(ms)), 3),
        "solve_ms_max": round(float(ms.max()), 3),
        "_times": record.solve_time,
        "_cpu": np.array([getattr(r, "cpu_time", np.nan) for r in reports]),
        "_violations": np.array([r.violation for r in reports if r.fallback == "soft"]),
    }


def infeasible_steps(scene: Scene, record: Any, epsilon: float, agent: Any) -> int:
    r"""Fallback steps of the episode certified infeasible (:func:`scenes.infeasible_step`, for a
    risk row that is the box clearance: $\epsilon = 0$)."""
    sc = scene.scenario(epsilon)
    count = 0
    for k in np.flatnonzero(record.fallback):
        last = np.asarray(sc.ego.initial_input) if k == 0 else record.actions[k - 1]
        measurement = (*record.object[k], sc.object.turn_rate)
        count += infeasible_step(sc, record.ego[k, :3], last, np.array(measurement), agent.backoff)
    return count


def summarise(agent: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """One agent's line of the summary."""
    steps = sum(r["steps"] for r in rows)
    ms = 1e3 * np.concatenate([r["_times"] for r in rows])
    collisions = sum(r["collided"] for r in rows)
    avoidable = sum(r["avoidable"] for r in rows)
    soft = sum(r["fallback_soft"] for r in rows)
    violations = np.concatenate([r["_violations"] for r in rows])
    manoeuvre = sum(r["fallback_manoeuvre"] for r in rows)
    return {
        "agent": agent,
        "scenes": len(rows),
        "steps": steps,
        "collisions": collisions,
        "avoidable": avoidable,
        "unavoidable": collisions - avoidable,
        "fallback_pct": round(100.0 * (soft + manoeuvre) / steps, 3),
        "soft_pct": round(100.0 * soft / steps, 3),
        "manoeuvre_pct": round(100.0 * manoeuvre / steps, 3),
        "penalty_steps": sum(r["penalty_steps"] for r in rows),
        "infeasible_pct": round(100.0 * sum(r["infeasible_steps"] for r in rows) / steps, 3)
        if all(r["infeasible_steps"] != "" for r in rows)
        else "",
        "failed_calls": sum(r["failed_calls"] for r in rows),
        "overran_calls": sum(r["overran_calls"] for r in rows),
        "over_cap_steps": sum(r["over_cap_steps"] for r in rows),
        "feasible_fallback_pct": round(
            100.0 * (soft + manoeuvre - sum(r["infeasible_steps"] for r in rows)) / steps, 3
        )
        if all(r["infeasible_steps"] != "" for r in rows)
        else "",
        "capped_steps": sum(r["capped_steps"] for r in rows),
        "solve_ms_p50": round(float(np.percentile(ms, 50)), 2),
        "solve_ms_p95": round(float(np.percentile(ms, 95)), 2),
        "solve_ms_p99": round(float(np.percentile(ms, 99)), 2),
        "solve_ms_max": round(float(ms.max()), 2),
        "cpu_ms_max": round(float(1e3 * np.nanmax(np.concatenate([r["_cpu"] for r in rows]))), 2),
        "soft_violation_median": round(float(np.median(violations)), 3) if violations.size else 0.0,
    }


def markdown(
    summary: list[dict[str, Any]], rows: list[dict[str, Any]], command: str, wall: float, where: str
) -> str:
    lines = [
        "# Stress benchmark: collisions, fallbacks and step times over random scenes",
        "",
        f"Command: `{command}`",
        "",
        f"Machine: {os.cpu_count()} cores, {where}, shared with whatever else ran (step times depend on it).",
        "",
        "Collisions: avoidable = some rate-limited open-loop manoeuvre from the start kept clear of the",
        "object's true motion for the whole episode (see `benchmarks/scenes.py`). Fallback levels as a",
        "share of all steps: soft = the risk rows softened by L1-penalised slacks, manoeuvre = the",
        "safest rate-limited manoeuvre. Penalty: steps whose hard calls failed but whose soft plan",
        "had zero slacks, so it solved the hard problem (the exact penalty; level (a), not a",
        "fallback). Failed calls: solver calls that did not converge (every attempt of a step).",
        "Infeasible: fallback steps certified infeasible (no input sequence within the rate limits",
        "clears the truncation box at some step n; for epsilon = 0, whose row is the box clearance), a",
        "share of all steps: a fallback must act there; not certified: the fallback steps not",
        "certified infeasible (the certificate is sufficient only, so an upper bound on the fallbacks",
        "where a plan may have existed). Overran: solver calls that ran past their iteration limit",
        "(fatrop ignores it at times; see `agents/mpc/nlp/budget.py`); > cap: steps longer than the cap",
        "`max_solve_time`. Capped: steps where the time cap cut a call",
        "short or left no time for one. Step time: the whole `predict` call [ms] (wall time; CPU max: the",
        "process's CPU time in the step, its own work, which the wall time exceeds when other processes",
        "ran).",
        "Violation: median over the soft steps of max_n s_n [m of clearance for these agents].",
        "",
        "| agent | method | eps | scenes | steps | collisions (avoidable / unavoidable) |"
        " fallback % (soft / manoeuvre) | infeasible % | not certified % | penalty | failed calls |"
        " overran | capped | > cap | p50 | p95 | p99 | max [ms] | CPU max [ms] | violation |",
        "|" + " --- |" * 20,
    ]
    lines.insert(-2, "<!-- --8<-- [start:summary] -->")
    for s in summary:
        name = agent(s["agent"])
        eps = "-" if name.tolerance is None else f"{name.tolerance:g}"
        lines.append(
            f"| {s['agent']} | {name.method} {name.variant} | {eps} | {s['scenes']} | {s['steps']} | "
            f"{s['collisions']} ({s['avoidable']} / {s['unavoidable']}) | "
            f"{s['fallback_pct']:.2f} ({s['soft_pct']:.2f} / {s['manoeuvre_pct']:.2f}) | "
            f"{'-' if s['infeasible_pct'] == '' else format(s['infeasible_pct'], '.2f')} | "
            f"{'-' if s['feasible_fallback_pct'] == '' else format(s['feasible_fallback_pct'], '.2f')} | "
            f"{s['penalty_steps']} | {s['failed_calls']} | {s['overran_calls']} | {s['capped_steps']} | "
            f"{s['over_cap_steps']} | {s['solve_ms_p50']:.1f} | "
            f"{s['solve_ms_p95']:.1f} | {s['solve_ms_p99']:.1f} | {s['solve_ms_max']:.1f} | "
            f"{s['cpu_ms_max']:.1f} | {s['soft_violation_median']:.2f} |"
        )
    lines.append("<!-- --8<-- [end:summary] -->")
    collided = [r for r in rows if r["collided"]]
    if collided:
        lines += [
            "",
            "## Collisions",
            "",
            "| agent | scene | uncertainty | kind | motion | v_ref | steps |"
            " avoidable | witness clearance [m] | fallback steps (soft / manoeuvre) |",
            "|" + " --- |" * 10,
        ]
        for r in collided:
            lines.append(
                f"| {r['agent']} | {r['scene']} | {r['uncertainty']} | {r['kind']} | {r['motion']} | "
                f"{r['v_ref']:g} | {r['steps']} | {'yes' if r['avoidable'] else 'no'} | "
                f"{r['witness_clearance']:.3f} | {r['fallback_soft']} / {r['fallback_manoeuvre']} |"
            )
    lines += ["", f"Wall time: {wall:.0f} s."]
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.stress`` (defaults shown in ``--help``)."""
    p = cli.parser("stress", __doc__)
    p.add_argument(
        "--family",
        default="scenes",
        choices=("scenes", "cap"),
        help="scenes: every agent on every scene; cap: one drawn agent per scene, every call checked",
    )
    p.add_argument("--scenes", type=cli.positive_int, default=200, help="number of random scenes per agent")
    p.add_argument("--seed", type=cli.nonnegative_int, default=0, help="seed of the scene family")
    p.add_argument(
        "--agents",
        default=None,
        help="comma list of rmpc[:RISK], smpc[:RISK][:SEVERITY:TOLERANCE][:budget=B]"
        f" (smpc:monte_carlo: slow); with --family cap, groups from {','.join(cap_family.GROUPS)}"
        f" (default: {','.join(DEFAULT_AGENTS)}; with --family cap, every group)",
    )
    p.add_argument(
        "--max-solve-time",
        type=cli.time_cap,
        default=None,
        help="wall-time cap of one MPC step [s] (default: the agents' own, 20%% of the sample time)",
    )
    p.add_argument("--solver", default=None, choices=("fatrop", "ipopt"), help="NLP solver (default: fatrop)")
    cli.add_output_options(
        p, Path("results"), "output folder (the committed run is in docs/results/stress/)", resume=True
    )
    cli.add_sweep_options(p)
    return p


def parse_args(argv: list[str] | None = None, p: argparse.ArgumentParser | None = None) -> argparse.Namespace:
    p = p or build_parser()
    args = p.parse_args(argv)
    if args.family == "cap":
        args.agents = list(cap_family.GROUPS) if args.agents is None else cli.comma_list(args.agents)
        if not args.agents:
            p.error("argument --agents: the list is empty")
        if bad := [a for a in args.agents if a not in cap_family.GROUPS]:
            p.error(f"argument --agents: unknown group(s) {bad}; expected from {list(cap_family.GROUPS)}")
        return args
    try:
        names = cli.agents_list(("rmpc", "smpc"))(
            ",".join(DEFAULT_AGENTS) if args.agents is None else args.agents
        )
    except argparse.ArgumentTypeError as error:
        p.error(f"argument --agents: {error}")
    args.agents = [str(agent(str(a))) for a in names]
    return args


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    p = build_parser()
    args = parse_args(argv, p)
    cap = args.family == "cap"
    out = cli.open_output(p, args, "cap" if cap else "stress", cap_family.FILES if cap else FILES, argv)
    options: dict[str, Any] = {}
    if args.max_solve_time is not None:
        options["max_solve_time"] = args.max_solve_time
    if args.solver is not None:
        options["solver"] = args.solver
    scenes = make_scenes(args.scenes, args.seed)
    if cap:
        return cap_family.run_family(args, scenes, out)
    jobs = [Job(a, s, tuple(sorted(options.items()))) for a in args.agents for s in scenes]
    with out:
        t0 = time.perf_counter()
        rows = run_sweep(run_job, jobs, args.workers, args.ray, desc="stress episodes", store=out.store)
        wall = time.perf_counter() - t0
        summary = [summarise(a, [r for r in rows if r["agent"] == a]) for a in args.agents]
        write_csv(out.dir / "stress.csv", EPISODE_COLUMNS, rows)
        write_csv(out.dir / "stress_summary.csv", SUMMARY_COLUMNS, summary)
        workers = args.workers or default_workers()
        where = "a Ray cluster" if args.ray is not False else f"{workers} worker process(es)"
        text = markdown(summary, rows, out.command_line.strip(), wall, where)
        (out.dir / "stress.md").write_text(text)
    print(text)
    print("Wrote:\n" + "\n".join(f"  {args.out / n}" for n in FILES))
    return summary


if __name__ == "__main__":
    main()
