r"""The stress benchmark's ``--family cap``: does every solver call stay within the step's cap?

    python -m benchmarks.stress --family cap --scenes 500 --workers 2 --out docs/results/cap

Setting $i$ pairs the stress scene $i$ (:func:`benchmarks.scenes.make_scenes`) with an agent drawn
from ``default_rng([seed, i, 7])``: the RMPC (a fifth of the settings), the exact SMPC (three
fifths) or the Monte Carlo SMPC (a fifth); one of the four severities; for an SMPC a tolerance
$\epsilon$ in {0, 0.05, 1} scales or none (``math.inf``, with a budget), an episode budget $B$ of none,
0 or {1e-5 (the smallest allowed), 5e-5, 1e-3, 0.1, 1, 1e6 (the largest)} scales and a risk weight
of none or {1e-3, 1, 1e3, 1e6 (the largest)} per scale (the scale: the severity's typical
magnitude, 1000 J for the paper's; 5e-5 scales = 0.05 J, 1e-3 = 1 J, 0.1 = 100 J there, the
budgets of the settings that hung). Episodes of at most :data:`MAX_STEPS` steps.

Every solver call is recorded (:attr:`agents.SolveReport.calls`): the table counts the calls past
their rung's iteration limit (``overran``) and the calls longer than twice the cap
``max_solve_time``, in wall time and in CPU time (a loaded machine stretches the wall time, not the
CPU time), with the calls' p50 / p99 / max; the steps over the cap; and the settings whose agent
was rejected with a named error or whose episode raised.
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.output import OutputSet, write_csv
from benchmarks.scenes import Scene
from benchmarks.sweep import default_workers, run_sweep

FILES = ("cap.csv", "cap_summary.csv", "cap.md")
"""The output set of ``stress --family cap``."""
GROUPS: dict[str, tuple[str, str]] = {
    "rmpc": ("RMPC", "worst_case"),
    "smpc": ("SMPC", "exact"),
    "smpc_mc": ("SMPC", "monte_carlo"),
}
"""Agent groups of the family -> (method, risk estimator)."""
SEVERITIES = ("paper", "plastic", "probability", "injury")
TOLERANCES = (0.0, 0.05, 1.0, math.inf)
r"""$\epsilon$ in scales (inf: no per-step bound; drawn only with a budget)."""
BUDGETS = (None, 0.0, 1e-5, 5e-5, 1e-3, 0.1, 1.0, 1e6)
"""$B$ in scales (None: no budget)."""
ALLOCATIONS = ("share", "horizon")
"""How a drawn budget is spent (``"horizon"``: the NLP's budget row and accumulator)."""
WEIGHTS = (None, 1e-3, 1.0, 1e3, 1e6)
"""w times the scale (None: no weight)."""
MAX_STEPS = 40
"""Steps per episode (the stress scenes' crossings happen within it)."""
MC_SAMPLES = 200
"""Monte Carlo draws per step of the ``smpc_mc`` group (its pilot: 100)."""
ROW_COLUMNS = (
    "group",
    "index",
    "uncertainty",
    "kind",
    "motion",
    "severity",
    "epsilon",
    "budget",
    "allocation",
    "weight",
    "outcome",
    "steps",
    "calls",
    "overran_calls",
    "iterations_past_limit",
    "calls_over_2cap",
    "calls_over_2cap_cpu",
    "call_ms_max",
    "call_cpu_ms_max",
    "steps_over_cap",
    "step_ms_max",
    "step_cpu_ms_max",
    "fallback_steps",
)
SUMMARY_COLUMNS = (
    "group",
    "settings",
    "rejected",
    "errors",
    "steps",
    "calls",
    "overran_calls",
    "calls_over_2cap",
    "calls_over_2cap_cpu",
    "call_ms_p50",
    "call_ms_p99",
    "call_ms_max",
    "call_cpu_ms_max",
    "steps_over_cap",
    "step_ms_p99",
    "step_ms_max",
    "step_cpu_ms_max",
    "fallback_pct",
)


@dataclass(frozen=True)
class Setting:
    """One agent of the family on one scene; the numbers in the severity's own unit."""

    group: str
    scene: Scene
    severity: str
    epsilon: float
    budget: float | None
    weight: float | None
    allocation: str = "share"
    """How the SMPC spends its budget (``"share"`` or ``"horizon"``: the NLP's budget row)."""

    def options(self) -> dict[str, Any]:
        """The agent's keyword arguments besides the env."""
        out: dict[str, Any] = {"risk_tolerance": self.epsilon}
        if self.budget is not None:
            out["risk_budget"] = self.budget
            out["budget_allocation"] = self.allocation
        if self.weight is not None:
            out["risk_weight"] = self.weight
        if self.group == "smpc_mc":
            out["samples"] = MC_SAMPLES
        return out


def make_settings(groups: list[str], count: int, seed: int, scenes: list[Scene]) -> list[Setting]:
    """``count`` settings drawn over ``groups`` (by the shares of the module), setting i on
    ``scenes[i]``."""
    from risk_env.risk.severity import make_severity
    from risk_env.scenario import Scenario

    out = []
    for i in range(count):
        rng = np.random.default_rng([seed, i, 7])
        share = rng.random()
        group = "rmpc" if share < 0.2 else "smpc_mc" if share >= 0.8 else "smpc"
        if group not in groups:
            group = groups[i % len(groups)]
        severity = SEVERITIES[int(rng.integers(len(SEVERITIES)))]
        scale = make_severity(Scenario(severity=severity)).scale
        budget = weight = None
        allocation = "share"
        if group == "rmpc":
            epsilon = float(TOLERANCES[int(rng.integers(3))])
        else:
            budget = BUDGETS[int(rng.integers(len(BUDGETS)))]
            weight = WEIGHTS[int(rng.integers(len(WEIGHTS)))]
            epsilon = float(TOLERANCES[int(rng.integers(4 if budget is not None else 3))])
            allocation = ALLOCATIONS[int(rng.integers(len(ALLOCATIONS)))]
        out.append(
            Setting(
                group,
                scenes[i],
                severity,
                epsilon * scale,
                None if budget is None else budget * scale,
                None if weight is None else weight / scale,
                allocation,
            )
        )
    return out


def run_setting(setting: Setting, extra: tuple[tuple[str, Any], ...] = ()) -> dict[str, Any]:
    """One episode of the setting's agent (with the ``extra`` options, e.g. ``max_solve_time``): its
    row, with every call's and step's times."""
    import gymnasium as gym

    import risk_env  # noqa: F401  (registers the env)
    from benchmarks.rollout import build_agent, rollout

    method, risk = GROUPS[setting.group]
    scene = setting.scene
    options = {**setting.options(), **dict(extra)}
    # the RMPC takes its epsilon from the scenario; the SMPC as an option (math.inf: none)
    epsilon = options.pop("risk_tolerance") if method == "RMPC" else 0.0
    scenario = scene.scenario(epsilon).replace(severity=setting.severity, max_steps=MAX_STEPS)
    env = gym.make("RiskCrossing-v0", scenario=scenario, object_motion=scene.motion)
    row: dict[str, Any] = {
        "group": setting.group,
        "index": scene.index,
        "uncertainty": scene.uncertainty,
        "kind": scene.kind,
        "motion": scene.motion,
        "severity": setting.severity,
        "epsilon": setting.epsilon,
        "budget": "" if setting.budget is None else setting.budget,
        "allocation": "" if setting.budget is None else setting.allocation,
        "weight": "" if setting.weight is None else setting.weight,
        "_call_ms": np.zeros(0),
        "_step_ms": np.zeros(0),
    }
    try:
        agent = build_agent(method, risk, env, seed=scene.index, **options)
    except ValueError as err:  # a named rejection of the setting (budget or weight out of range)
        return {**row, "outcome": f"rejected: {err}", "steps": 0, "calls": 0}
    try:
        record = rollout(agent, env, seed=scene.seed)
    except Exception as err:  # counted, not hidden: an episode must never raise
        return {**row, "outcome": f"error: {type(err).__name__}: {err}", "steps": 0, "calls": 0}
    finally:
        env.close()
    reports = [r for r in record.reports if r is not None]
    calls = [c for r in reports for c in r.calls]
    cap = agent.max_solve_time
    wall = np.array([c.wall_time for c in calls])
    cpu = np.array([c.cpu_time for c in calls])
    step_cpu = np.array([r.cpu_time for r in reports])
    return {
        **row,
        "outcome": "ok",
        "steps": record.steps,
        "calls": len(calls),
        "overran_calls": sum(c.overran for c in calls),
        "iterations_past_limit": max((c.iterations - c.limit for c in calls), default=0),
        "calls_over_2cap": int(np.sum(wall > 2.0 * cap)),
        "calls_over_2cap_cpu": int(np.sum(cpu > 2.0 * cap)),
        "call_ms_max": round(1e3 * float(wall.max(initial=0.0)), 3),
        "call_cpu_ms_max": round(1e3 * float(cpu.max(initial=0.0)), 3),
        "steps_over_cap": int(np.sum(record.solve_time > cap)),
        "step_ms_max": round(1e3 * float(record.solve_time.max(initial=0.0)), 3),
        "step_cpu_ms_max": round(1e3 * float(step_cpu.max(initial=0.0)), 3),
        "fallback_steps": int(np.sum(record.fallback)),
        "_call_ms": 1e3 * wall,
        "_step_ms": 1e3 * record.solve_time,
    }


def summarise(group: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """One group's line of the summary."""
    ran = [r for r in rows if r["outcome"] == "ok"]
    calls = np.concatenate([r["_call_ms"] for r in ran]) if ran else np.zeros(0)
    steps = np.concatenate([r["_step_ms"] for r in ran]) if ran else np.zeros(0)
    n_steps = sum(r["steps"] for r in ran)

    def pct(values: np.ndarray, q: float) -> float:
        return round(float(np.percentile(values, q)), 2) if values.size else 0.0

    return {
        "group": group,
        "settings": len(rows),
        "rejected": sum(r["outcome"].startswith("rejected") for r in rows),
        "errors": sum(r["outcome"].startswith("error") for r in rows),
        "steps": n_steps,
        "calls": int(calls.size),
        "overran_calls": sum(r["overran_calls"] for r in ran),
        "calls_over_2cap": sum(r["calls_over_2cap"] for r in ran),
        "calls_over_2cap_cpu": sum(r["calls_over_2cap_cpu"] for r in ran),
        "call_ms_p50": pct(calls, 50),
        "call_ms_p99": pct(calls, 99),
        "call_ms_max": round(float(calls.max(initial=0.0)), 2),
        "call_cpu_ms_max": max((r["call_cpu_ms_max"] for r in ran), default=0.0),
        "steps_over_cap": sum(r["steps_over_cap"] for r in ran),
        "step_ms_p99": pct(steps, 99),
        "step_ms_max": round(float(steps.max(initial=0.0)), 2),
        "step_cpu_ms_max": max((r["step_cpu_ms_max"] for r in ran), default=0.0),
        "fallback_pct": round(100.0 * sum(r["fallback_steps"] for r in ran) / n_steps, 2) if n_steps else 0.0,
    }


def markdown(
    summary: list[dict[str, Any]],
    rows: list[dict[str, Any]],
    command: str,
    wall: float,
    where: str,
    cap: float | None = None,
) -> str:
    """The family's report: the command, the summary table, the settings that did not run."""
    lines = [
        "# Stress benchmark, family cap: every solver call within the step's cap?",
        "",
        f"Command: `{command}`",
        "",
        f"Machine: {where}, shared with whatever else ran (wall times depend on it; CPU times less).",
        "",
        "Settings: stress scenes with agents drawn over severities, tolerances, episode budgets and risk",
        f"weights (`benchmarks/cap_family.py`), episodes of at most {MAX_STEPS} steps, a cap of",
        ("the agents' default (100 ms)" if cap is None else f"{1e3 * cap:g} ms")
        + ". Overran: calls past their rung's iteration limit. > 2 cap: calls longer than twice",
        "the cap, by wall time and by the process's CPU time. Call and step times in ms. Rejected:",
        "agents refused with a named error (a budget or weight out of range); errors: episodes that",
        "raised.",
        "",
        "<!-- --8<-- [start:summary] -->",
        "| group | settings | rejected | errors | steps | calls | overran | calls > 2 cap (wall / CPU) |"
        " call p50 | call p99 | call max | call CPU max | steps > cap | step p99 | step max |"
        " step CPU max | fallback % |",
        "|" + " --- |" * 17,
    ]
    for s in summary:
        lines.append(
            f"| {s['group']} | {s['settings']} | {s['rejected']} | {s['errors']} | {s['steps']} | "
            f"{s['calls']} | {s['overran_calls']} | {s['calls_over_2cap']} / {s['calls_over_2cap_cpu']} | "
            f"{s['call_ms_p50']:.1f} | {s['call_ms_p99']:.1f} | {s['call_ms_max']:.1f} | "
            f"{s['call_cpu_ms_max']:.1f} | {s['steps_over_cap']} | {s['step_ms_p99']:.1f} | "
            f"{s['step_ms_max']:.1f} | {s['step_cpu_ms_max']:.1f} | {s['fallback_pct']:.2f} |"
        )
    lines.append("<!-- --8<-- [end:summary] -->")
    odd = [r for r in rows if r["outcome"] != "ok"]
    if odd:
        lines += [
            "",
            "## Settings that did not run",
            "",
            "| group | scene | severity | budget | weight | outcome |",
        ]
        lines.append("|" + " --- |" * 6)
        for r in odd:
            cells = (r["group"], r["index"], r["severity"], r["budget"], r["weight"], r["outcome"])
            lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    lines += ["", f"Wall time: {wall:.0f} s."]
    return "\n".join(lines) + "\n"


def run_family(args: argparse.Namespace, scenes: list[Scene], out: OutputSet) -> list[dict[str, Any]]:
    """``python -m benchmarks.stress --family cap``: one drawn agent per scene; writes :data:`FILES`
    into the output set ``out``."""
    settings = make_settings(args.agents, args.scenes, args.seed, scenes)
    extra = {"max_solve_time": args.max_solve_time, "solver": args.solver}
    run = functools.partial(run_setting, extra=tuple((k, v) for k, v in extra.items() if v is not None))
    with out:
        t0 = time.perf_counter()
        rows = run_sweep(run, settings, args.workers, args.ray, desc="cap settings", store=out.store)
        wall = time.perf_counter() - t0
        summary = [summarise(g, [r for r in rows if r["group"] == g]) for g in args.agents]
        write_csv(out.dir / "cap.csv", ROW_COLUMNS, rows)
        write_csv(out.dir / "cap_summary.csv", SUMMARY_COLUMNS, summary)
        workers = args.workers or default_workers()
        where = f"{os.cpu_count()} cores, " + (
            "a Ray cluster" if args.ray is not False else f"{workers} worker(s)"
        )
        text = markdown(summary, rows, out.command_line.strip(), wall, where, args.max_solve_time)
        (out.dir / "cap.md").write_text(text)
    print(text)
    print("Wrote:\n" + "\n".join(f"  {args.out / n}" for n in FILES))
    return summary
