"""The intersection commands' tables: one summary row per agent and predictor, as Markdown and CSV.

Rates carry Wilson 95 % intervals (:func:`benchmarks.sampled_rows.wilson`). Solve times are per
MPC step, CPU time (``SolveReport.cpu_time``: the step's own work, whatever else the machine
runs) beside wall time, over the steps that built no NLP (an MPC builds each size of its problem
when a step first needs it: those steps are counted apart, ``build_steps``). The realised episode
risk of an SMPC with a budget is what it spent by its own estimator (``spent_risk()`` at the
episode's end), set against its budget B.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.agent_names import REFERENCES
from benchmarks.highway_agents import resolve
from benchmarks.sampled_rows import wilson

RATES = ("collision", "ego_into_vehicle", "vehicle_into_ego", "goal", "timeout", "deadlock", "off_road")
"""The per-episode outcomes counted, each with its rate and Wilson interval."""
EPISODE_FIELDS = (
    "agent", "predictor", "seed", "steps", "time_s", "collision", "ego_into_vehicle",
    "vehicle_into_ego", "goal", "timeout", "deadlock", "jammed", "wrecked", "off_road", "off_road_steps",
    "final_speed",
    "risk_mean", "fallbacks", "manoeuvres", "reset_cpu_s", "spent_risk", "solve_ms_median", "cpu_ms_median",
    "build_steps", "gate_steps",
)  # fmt: skip
"""The columns of the per-episode CSV."""


def _stat(a: np.ndarray, q: float) -> float:
    return float(np.percentile(a, q)) if a.size else float("nan")


def summarise(
    name: str, predictor: str, rows: list[dict[str, Any]], args: argparse.Namespace
) -> dict[str, Any]:
    """One agent's (and predictor's) row of the summary, from its episodes ``rows``."""
    agent = resolve(name, args.severity, args.budget)
    n = len(rows)
    built = np.concatenate([r["built"] for r in rows]).astype(bool)
    wall = np.concatenate([r["solve_times"] for r in rows])[~built] * 1e3
    cpu = np.concatenate([r["cpu_times"] for r in rows])[~built] * 1e3
    full = np.concatenate([r["full"] for r in rows])[~built] if wall.size else np.zeros(0, bool)
    goals = [r["time_s"] for r in rows if r["goal"]]
    risk = np.concatenate([r["risk_steps"] for r in rows])
    out: dict[str, Any] = {"agent": name, "predictor": predictor, "label": agent.label, "episodes": n}
    for key in RATES:
        k = int(sum(r[key] for r in rows))
        lo, hi = wilson(k, n)
        out |= {key: k, f"{key}_rate": k / n, f"{key}_ci_low": lo, f"{key}_ci_high": hi}
    fallbacks = np.array([r["fallbacks"] for r in rows])
    mpc_steps = int(sum(r["mpc_steps"] for r in rows))
    out |= {
        "time_to_goal_s": float(np.mean(goals)) if goals else float("nan"),
        "steps": int(risk.size),
        "mpc_steps": mpc_steps,
        "fallbacks": int(fallbacks.sum()),
        "fallback_share": float(fallbacks.sum() / mpc_steps) if mpc_steps else float("nan"),
        "episodes_with_fallback": int(np.sum(fallbacks > 0)),
        "manoeuvre_steps": int(sum(r.get("manoeuvres", 0) for r in rows)),
        "risk_mean": float(risk.mean()) if risk.size else 0.0,
        "jammed": int(sum(bool(r.get("jammed", False)) for r in rows)),
        "deadlock_jammed": int(sum(bool(r["deadlock"] and r.get("jammed", False)) for r in rows)),
    }
    # episodes run before the count existed (resumed chunks) leave it unknown, never 0
    known = all("wrecked" in r for r in rows)
    out["wrecked"] = int(sum(bool(r["wrecked"]) for r in rows)) if known else None
    out["deadlock_wrecked"] = int(sum(bool(r["deadlock"] and r["wrecked"]) for r in rows)) if known else None
    for kind, times in (("cpu", cpu), ("solve", wall)):
        out |= {
            f"{kind}_ms_median": _stat(times, 50),
            f"{kind}_ms_p95": _stat(times, 95),
            f"{kind}_ms_max": float(times.max()) if times.size else float("nan"),
            f"full_{kind}_ms_median": _stat(times[full], 50),
            f"full_{kind}_ms_p95": _stat(times[full], 95),
        }
    out |= {"full_steps": int(full.sum()), "build_steps": int(built.sum())}
    return out | budget_columns(agent.budget, rows)


def budget_columns(budget: float | None, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The realised episode risk against ``budget`` B (empty values without one): mean and
    largest spent risk, episodes over B and how many of those had a fallback step."""
    if budget is None:
        return {
            "budget": "",
            "spent_mean": "",
            "spent_max": "",
            "over_budget": "",
            "over_budget_fallback": "",
        }
    spent = np.array([r["spent_risk"] for r in rows])
    over = spent > budget
    fell = np.array([r["fallbacks"] > 0 for r in rows])
    return {
        "budget": budget,
        "spent_mean": float(spent.mean()),
        "spent_max": float(spent.max()),
        "over_budget": int(over.sum()),
        "over_budget_fallback": int(np.sum(over & fell)),
    }


def _f(x: Any, digits: int = 1) -> str:
    return "-" if x == "" or x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def _wrecks(s: dict[str, Any]) -> str:
    """``wrecked (deadlock_wrecked)``, or "n/a" where the episodes did not count them."""
    return "n/a" if s.get("wrecked") is None else f"{s['wrecked']} ({s['deadlock_wrecked']})"


def rate_ci(s: dict[str, Any], key: str) -> str:
    """The rate ``key`` of summary row ``s`` with its Wilson interval, in %; "n/a" where the row did
    not count it (a summary made before the count existed)."""
    parts = [s.get(f"{key}_{part}", "") for part in ("rate", "ci_low", "ci_high")]
    if any(p == "" or p is None for p in parts):
        return "n/a"
    rate, low, high = (100 * float(p) for p in parts)
    return f"{rate:.1f}% [{low:.1f}, {high:.1f}]"


def _who(s: dict[str, Any]) -> str:
    return s["agent"] + (f" ({s['predictor']})" if s["predictor"] else "")


def markdown(summary: list[dict[str, Any]], args: argparse.Namespace, wall: float, command: str) -> str:
    """The summary as two Markdown tables (outcomes; the planners' steps) with the settings."""
    cap = "20 % of T (the default)" if args.max_solve_time is None else f"{args.max_solve_time:g} s"
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    lines = [
        f"`{command}`",
        "",
        f"{args.env} (INTERSECTION_CONFIG; duration {args.duration:g} s, spawn probability"
        f" {args.spawn_probability:g}, {args.initial_vehicles} initial vehicles), seeds"
        f" {args.seed}..{args.seed + args.episodes - 1} (N = {args.episodes} per agent, the same for"
        f" all), uncertainty {args.uncertainty}, {args.slots} object slots, mode threshold"
        f" {args.mode_threshold:g}, budget share {args.budget_share:g}"
        f", corridor {getattr(args, 'corridor', 1.0):g} m"
        f", junction gate {'on' if getattr(args, 'gate', True) else 'off'}"
        f"{'' if getattr(args, 'lane_pieces', 1) == 1 else f', lane predictor in {args.lane_pieces} pieces'}"
        f"{', interval switches on: ' + ', '.join(args.interval) if getattr(args, 'interval', ()) else ''}"
        f"{', turn signals observed' if getattr(args, 'signals', False) else ''}"
        f"{radius_text(args)}"
        f"{gate_text(args)}"
        "; the MPCs plan with the"
        f" predictor in brackets. Risk scored by RiskCostWrapper (exact, severity {args.severity},"
        f" predictor {args.predictor[0]}). The MPCs' wall-time cap per step: {cap}. Wall time"
        f" {wall:.0f} s on {args.workers or 'all'} worker(s); load average at the end (1 / 5 / 15"
        f" min): {load} on {os.cpu_count()} cores. Rates: % [Wilson 95 % interval]. Deadlock: no"
        " collision, no goal, the ego stopped (< 0.1 m/s) over the last 10 s; jammed: no collision, no goal,"
        " another vehicle stopped inside the junction over the last 10 s; behind a wreck: no collision, no"
        " goal, a vehicle that crashed into another stands on the ego's way (its centre within 2.5 m of the"
        " route ahead). Left the road: off every"
        " lane of the map at some step.",
        "",
    ]
    for s in summary:
        lines.append(f"- `{_who(s)}`: {s['label']}")
    lines += [
        "",
        "| agent | N | collisions | ego drove into a vehicle | a vehicle drove into the ego | goal |"
        " timeout | deadlocks | timeouts jammed (of which deadlocks) | behind a wreck (of which deadlocks) |"
        " left the road | time to goal [s] |",
        "| " + " | ".join(["---"] * 12) + " |",
    ]
    for s in summary:
        lines.append(
            f"| {_who(s)} | {s['episodes']} | {rate_ci(s, 'collision')} | {rate_ci(s, 'ego_into_vehicle')} |"
            f" {rate_ci(s, 'vehicle_into_ego')} | {rate_ci(s, 'goal')} | {100 * s['timeout_rate']:.1f}% |"
            f" {s['deadlock']} | {s['jammed']} ({s['deadlock_jammed']}) | {_wrecks(s)} | {s['off_road']} |"
            f" {_f(s['time_to_goal_s'])} |"
        )
    mpcs = [s for s in summary if s["agent"] not in REFERENCES]
    if not mpcs:
        return "\n".join(lines) + "\n"
    lines += [
        "",
        "| agent | fallback steps (share of steps; episodes with any; of which manoeuvres) | episode risk:"
        " budget B, mean / max, episodes over B (with a fallback) | solve CPU ms median / p95 / max |"
        f" solve wall ms median / p95 / max | CPU ms, all {args.slots} slots occupied: median / p95 (steps) |"
        " steps that built an NLP (not timed) | risk per step (scored) |",
        "| " + " | ".join(["---"] * 8) + " |",
    ]
    for s in mpcs:
        fb = f"{s['fallbacks']} ({100 * s['fallback_share']:.2f}%; {s['episodes_with_fallback']};"
        fb += f" {s['manoeuvre_steps']})"
        spent = (
            "-"
            if s["budget"] == ""
            else f"{s['budget']:g}: {s['spent_mean']:.3g} / {s['spent_max']:.3g},"
            f" {s['over_budget']} ({s['over_budget_fallback']})"
        )
        times = {
            k: f"{_f(s[f'{k}_ms_median'])} / {_f(s[f'{k}_ms_p95'])} / {_f(s[f'{k}_ms_max'], 0)}"
            for k in ("cpu", "solve")
        }
        full = f"{_f(s['full_cpu_ms_median'])} / {_f(s['full_cpu_ms_p95'])} ({s['full_steps']})"
        lines.append(
            f"| {_who(s)} | {fb} | {spent} | {times['cpu']} | {times['solve']} | {full} |"
            f" {s['build_steps']} | {s['risk_mean']:.3g} |"
        )
    return "\n".join(lines) + "\n"


def write_csvs(folder: Path, prefix: str, summary: list[dict[str, Any]], rows: list[dict[str, Any]]) -> None:
    """``PREFIX.csv`` (the summary) and ``PREFIX_episodes.csv`` (one row per episode) in ``folder``."""
    with open(folder / f"{prefix}.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(summary[0]))
        writer.writeheader()
        writer.writerows(summary)
    with open(folder / f"{prefix}_episodes.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(EPISODE_FIELDS))
        writer.writeheader()
        for r in rows:
            timed = {f"{k}_ms_median": r[f"{k}_times"][~r["built"]] for k in ("solve", "cpu")}
            medians = {k: 1e3 * float(np.median(t)) if t.size else "" for k, t in timed.items()}
            medians["build_steps"] = int(r["built"].sum())
            writer.writerow({k: r.get(k, "") for k in EPISODE_FIELDS if k not in medians} | medians)


def gate_text(args: Any) -> str:
    """The gate's settings where the options change them (for the table's header), else ""."""
    from benchmarks.highway_agents import gate_settings
    from risk_env.highway.gate_judge import GateSettings

    settings = gate_settings(args)
    if not settings or settings == GateSettings():
        return ""
    changed = {k: v for k, v in vars(settings).items() if v != getattr(GateSettings(), k)}
    return ", gate " + ", ".join(f"{k} {v}" for k, v in changed.items())


def radius_text(args: Any) -> str:
    """The MPCs' object disc radius and turning where the options change them (for the table's header),
    else ""."""
    from benchmarks.highway_agents import ADAPTER_OBJECT_RADIUS

    radius = getattr(args, "object_radius", ADAPTER_OBJECT_RADIUS)
    discs = getattr(args, "car_discs", 1)
    turning = ", the MPCs turning as the car does" if getattr(args, "car_turning", False) else ""
    turning += ", restarting standing plans" if getattr(args, "restart_standing", False) else ""
    if discs > 1:
        return f", the MPCs' cars {discs} discs each{turning}"
    return turning if radius == ADAPTER_OBJECT_RADIUS else f", the MPCs' object discs {radius:g} m{turning}"
