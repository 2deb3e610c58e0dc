"""Our agents in highway-env: RMPC and SMPC drive ``intersection-v2`` against highway-env's IDM.

    python -m benchmarks.highway_intersection --episodes 4 --agents rmpc,idm     # a quick look
    python -m benchmarks.highway_intersection --episodes 200 --out docs/results/highway \\
        --agents rmpc,smpc:probability:0.01,idm

Each agent drives the controlled vehicle of ``intersection-v2`` (``--env intersection-v1``
selectable; :data:`~risk_env.highway.adapter.INTERSECTION_CONFIG`: the kinematic vehicle with
continuous actions, T = 0.5 s, highway-env's traffic, the left turn to ``"o1"``, 13 s) over the
same seeded episodes (seeds S..S+E-1; the traffic then reacts to the ego). Agents (``--agents``,
named as in every command, :mod:`benchmarks.agent_names`):

- ``rmpc[:RISK]``: :class:`agents.RMPC` (default: worst case, exact box form) through
  :class:`IntersectionAdapter` with ``--slots`` object slots (default 5): one solve plans against
  every observed vehicle, the nearest first, up to the slot count;
- ``smpc[:RISK][:SEVERITY:TOLERANCE]``: :class:`agents.SMPC` (default: exact risk) through the
  adapter, with its own severity and epsilon (default: ``--severity``, ``--tolerance``), e.g.
  ``smpc:probability:0.01`` (a collision chance of at most 1 % per step under the prediction) or
  ``smpc:injury:0.001``;
- ``idm``: :class:`IDMEgo`, highway-env's ``IDMVehicle`` on the same route (its reference driver).

**Collision kinds** (from the simulator's states at the start of the step that ended in the
crash): with d the unit vector from the ego's centre to the centre of the vehicle it hit (the
crashed vehicle nearest the ego), the ego's closing speed is ``v_e . d`` and the other's
``-v_o . d`` (velocities along each heading). The ego *drove into* the vehicle when its closing
speed exceeds the other's; otherwise the vehicle *drove into the ego* (rear-ended, or hit while
stopped or yielding). Rates carry Wilson 95 % intervals.

Reported per agent: collisions by kind, goal rate (arrived on the road to ``"o1"``), time to goal,
timeouts, the MPC's fallbacks (soft or manoeuvre steps) per episode, solve time per step (median /
p95 / max; and over the steps with every slot occupied), and the risk scored by
:class:`RiskCostWrapper` (exact) with ``--severity``. Episodes run in a process pool
(:mod:`benchmarks.sweep`, ``--workers``). Outputs in ``--out``: ``intersection.md``,
``intersection.csv`` (summary) and ``intersection_episodes.csv``, one output set
(:mod:`benchmarks.output`; ``--resume`` goes on after an interruption).
"""

from __future__ import annotations

import argparse
import csv
import functools
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cli
from benchmarks.agent_names import AgentName, parse_agent
from benchmarks.sampled_rows import wilson
from benchmarks.sweep import run_sweep
from risk_env.risk.severity import check_tolerance
from risk_env.scenario.scenario import SEVERITY_NAMES, UNCERTAINTY_PRESETS

KINDS = ("rmpc", "smpc", "idm")
FILES = ("intersection.csv", "intersection.md", "intersection_episodes.csv")
"""The files a run writes in ``--out``."""
ENVS = ("intersection-v2", "intersection-v1")
CHUNK = 5
"""Episodes per pool job (each process keeps its env and agents between jobs)."""
_CACHE: dict[tuple[Any, ...], tuple[Any, Any]] = {}


def agent(spec: str, args: argparse.Namespace) -> AgentName:
    """The agent ``spec`` names, an SMPC without its own severity and tolerance given ``--severity``
    and ``--tolerance``."""
    return parse_agent(spec, KINDS, budget=False).with_defaults(args.severity, args.tolerance)


def label(spec: str, args: argparse.Namespace) -> str:
    """``"smpc:injury:0.001"`` -> ``"SMPC (exact risk), injury severity, epsilon 0.001"``."""
    a = agent(spec, args)
    if a.kind == "idm":
        return "highway-env IDM"
    risk = a.variant.replace("_", " ")
    if a.kind == "rmpc":
        return f"RMPC ({risk} risk)"
    return f"SMPC ({risk} risk), {a.severity} severity, epsilon {a.tolerance:g}"


def make_driver(spec: str, env: Any, args: argparse.Namespace) -> Any:
    """The driver ``spec`` (see the module docstring) for ``env``."""
    from agents import RMPC, SMPC
    from risk_env.highway import IDMEgo, IntersectionAdapter

    a = agent(spec, args)
    if a.kind == "idm":
        return IDMEgo(env)
    factory = functools.partial(RMPC if a.kind == "rmpc" else SMPC, risk=a.variant)
    if args.max_solve_time is not None:
        factory = functools.partial(factory, max_solve_time=args.max_solve_time)
    return IntersectionAdapter(
        env,
        factory,
        uncertainty=args.uncertainty,
        risk_tolerance=args.tolerance if a.tolerance is None else a.tolerance,
        severity=a.severity or args.severity,
        slots=args.slots,
    )


def _states(base: Any) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Position and velocity (along the heading) of every vehicle, by identity."""
    out = {}
    for v in base.road.vehicles:
        vel = float(v.speed) * np.array([np.cos(v.heading), np.sin(v.heading)])
        out[id(v)] = (np.array(v.position, dtype=float), vel)
    return out


def crash_kind(base: Any, before: dict[int, tuple[np.ndarray, np.ndarray]]) -> str:
    """``"ego"`` (the ego drove into the vehicle) or ``"other"`` (it drove into the ego), from the
    states ``before`` the crash step (see the module docstring)."""
    ego = base.vehicle
    hit = [v for v in base.road.vehicles if v is not ego and v.crashed] or [
        v for v in base.road.vehicles if v is not ego
    ]
    other = min(hit, key=lambda v: float(np.hypot(*(v.position - ego.position))))
    p_e, v_e = before.get(id(ego), (np.array(ego.position), np.zeros(2)))
    p_o, v_o = before.get(id(other), (np.array(other.position), np.zeros(2)))
    d = p_o - p_e
    d = d / max(float(np.hypot(*d)), 1e-9)
    return "ego" if float(v_e @ d) > float(-v_o @ d) else "other"


def run_episode(driver: Any, env: Any, seed: int, slots: int) -> dict[str, Any]:
    """One episode; returns its row (metrics and per-step arrays)."""
    from risk_env.highway.adapter import reached

    obs, _ = env.reset(seed=seed)
    if hasattr(driver, "reset"):
        driver.reset()
    base = env.unwrapped
    risks, times, full = [], [], []
    done, kind = False, ""
    while not done:
        action, _ = driver.predict(obs)
        if getattr(driver, "last_solve", None) is not None:
            times.append(driver.last_solve_time)
            full.append(len(driver.last_objects) >= slots)
        before = _states(base)
        obs, _, terminated, truncated, info = env.step(action)
        risks.append(info["risk"])
        done = terminated or truncated
        if base.vehicle.crashed and not kind:
            kind = crash_kind(base, before)
    crashed = bool(base.vehicle.crashed)
    goal = reached(env, driver.destination)
    risks = np.array(risks)
    return {
        "seed": seed,
        "steps": len(risks),
        "time_s": float(base.time),
        "collision": crashed,
        "ego_into_vehicle": crashed and kind == "ego",
        "vehicle_into_ego": crashed and kind == "other",
        "goal": goal,
        "timeout": not crashed and not goal,
        "risk_mean": float(risks.mean()) if len(risks) else 0.0,
        "risk_steps": risks,
        "solve_times": np.array(times),
        "full": np.array(full, dtype=bool),
        "fallbacks": int(getattr(driver, "failures", 0)),
    }


def run_chunk(job: tuple[str, list[int], argparse.Namespace]) -> list[dict[str, Any]]:
    """Episodes ``seeds`` of agent ``spec`` (a pool job; the env and driver kept per process)."""
    spec, seeds, args = job
    key = (spec, args.env, args.uncertainty, args.severity, args.tolerance, args.slots, args.max_solve_time)
    if key not in _CACHE:
        from risk_env.highway import RiskCostWrapper, make_intersection_env
        from risk_env.highway.adapter import ADAPTER_DEFAULTS

        radii = {k: ADAPTER_DEFAULTS[k] for k in ("ego_radius", "object_radius")}
        env = RiskCostWrapper(
            make_intersection_env(version=args.env),
            uncertainty=args.uncertainty,
            estimator="exact",
            risk_tolerance=args.tolerance,
            severity=args.severity,
            **radii,
        )
        _CACHE[key] = (env, make_driver(spec, env, args))
    env, driver = _CACHE[key]
    out = []
    for seed in seeds:
        row = run_episode(driver, env, seed, args.slots)
        row.update(agent=spec)
        out.append(row)
    return out


def _ci(k: int, n: int) -> str:
    lo, hi = wilson(k, n)
    return f"{100 * k / n:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]"


def summarise(spec: str, rows: list[dict[str, Any]], args: argparse.Namespace) -> dict[str, Any]:
    """One agent's row of the summary table."""
    n = len(rows)
    solve = np.concatenate([r["solve_times"] for r in rows]) * 1e3
    full = np.concatenate([r["full"] for r in rows]) if solve.size else np.zeros(0, bool)
    goals = [r["time_s"] for r in rows if r["goal"]]
    risk = np.concatenate([r["risk_steps"] for r in rows])

    def stat(a: np.ndarray, q: float) -> float:
        return float(np.percentile(a, q)) if a.size else float("nan")

    out: dict[str, Any] = {"agent": spec, "label": label(spec, args), "episodes": n}
    for key in ("collision", "ego_into_vehicle", "vehicle_into_ego"):
        k = sum(r[key] for r in rows)
        lo, hi = wilson(k, n)
        out |= {key: k, f"{key}_rate": k / n, f"{key}_ci_low": lo, f"{key}_ci_high": hi}
    fallbacks = np.array([r["fallbacks"] for r in rows])
    return out | {
        "goal_rate": sum(r["goal"] for r in rows) / n,
        "timeout_rate": sum(r["timeout"] for r in rows) / n,
        "time_to_goal_s": float(np.mean(goals)) if goals else float("nan"),
        "fallbacks": int(fallbacks.sum()),
        "fallbacks_per_episode": float(fallbacks.mean()),
        "episodes_with_fallback": int(np.sum(fallbacks > 0)),
        "risk_mean": float(risk.mean()) if risk.size else 0.0,
        "solve_ms_median": stat(solve, 50),
        "solve_ms_p95": stat(solve, 95),
        "solve_ms_max": float(solve.max()) if solve.size else float("nan"),
        "full_steps": int(full.sum()),
        "full_solve_ms_median": stat(solve[full], 50),
        "full_solve_ms_p95": stat(solve[full], 95),
        "steps": int(risk.size),
    }


def _f(x: float, digits: int = 1) -> str:
    return "-" if np.isnan(x) else f"{x:.{digits}f}"


def markdown(summary: list[dict[str, Any]], args: argparse.Namespace, wall: float, command: str) -> str:
    """The summary as a Markdown table with its settings and command."""
    cap = "20 % of T (the default)" if args.max_solve_time is None else f"{args.max_solve_time:g} s"
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    lines = [
        f"`{command}`",
        "",
        f"{args.env} (INTERSECTION_CONFIG), seeds {args.seed}..{args.seed + args.episodes - 1}"
        f" (N = {args.episodes} per agent), uncertainty {args.uncertainty}, {args.slots} object slots;"
        f" risk scored by RiskCostWrapper (exact, severity {args.severity}). Wall time {wall:.0f} s"
        f" on {args.workers or 'all'} worker(s); the MPCs' wall-time cap per step: {cap}; the machine's"
        f" load average at the end (1 / 5 / 15 min): {load} on {os.cpu_count()} cores (solve times are"
        " wall times: other processes on the machine lengthen them). Collisions: % [Wilson 95 %"
        " interval].",
        "",
        "| agent | N | collisions | ego drove into a vehicle | a vehicle drove into the ego | goal |"
        " timeout | time to goal [s] | fallbacks (episodes with any) | solve ms median / p95 / max |"
        f" solve ms, all {args.slots} slots occupied: median / p95 (steps) |",
        "| " + " | ".join(["---"] * 11) + " |",
    ]
    for s in summary:
        idm = s["agent"] == "idm"
        n = s["episodes"]
        solve = (
            "-"
            if idm
            else f"{_f(s['solve_ms_median'])} / {_f(s['solve_ms_p95'])} / {_f(s['solve_ms_max'], 0)}"
        )
        full = (
            "-"
            if idm
            else f"{_f(s['full_solve_ms_median'])} / {_f(s['full_solve_ms_p95'])} ({s['full_steps']})"
        )
        fb = "-" if idm else f"{s['fallbacks']} ({s['episodes_with_fallback']})"
        lines.append(
            f"| {s['agent']} | {n} | {_ci(s['collision'], n)} | {_ci(s['ego_into_vehicle'], n)} |"
            f" {_ci(s['vehicle_into_ego'], n)} | {100 * s['goal_rate']:.1f}% |"
            f" {100 * s['timeout_rate']:.1f}% |"
            f" {_f(s['time_to_goal_s'])} | {fb} | {solve} | {full} |"
        )
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.highway_intersection``."""
    parser = cli.parser("highway_intersection", __doc__)
    parser.add_argument("--episodes", type=cli.positive_int, default=200, help="seeded episodes per agent")
    parser.add_argument("--seed", type=cli.nonnegative_int, default=0, help="first seed")
    parser.add_argument("--env", choices=ENVS, default=ENVS[0], help="highway-env intersection")
    parser.add_argument(
        "--agents",
        type=cli.agents_list(KINDS, budget=False),
        default="rmpc,smpc:probability:0.01,idm",
        help="comma list of rmpc[:RISK], smpc[:RISK][:SEVERITY:TOLERANCE], idm",
    )
    parser.add_argument("--slots", type=cli.positive_int, default=5, help="the MPC's object slots")
    parser.add_argument("--uncertainty", choices=UNCERTAINTY_PRESETS, default="low", help="Table I level")
    parser.add_argument("--severity", choices=SEVERITY_NAMES, default="probability", help="severity model")
    parser.add_argument(
        "--tolerance", type=cli.nonnegative_float, default=0.01, help="epsilon [units of the severity]"
    )
    parser.add_argument(
        "--max-solve-time",
        type=cli.time_cap,
        default=None,
        help="the MPCs' wall-time cap per step [s] (default: theirs, 20 %% of T; inf: none, results"
        " independent of the machine's load)",
    )
    parser.add_argument(
        "--workers", type=cli.positive_int, default=None, help="processes (default: all cores)"
    )
    cli.add_output_options(parser, Path("results/highway"), "output folder", resume=True)
    return parser


def parse_args(
    argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None
) -> argparse.Namespace:
    parser = parser or build_parser()
    args = parser.parse_args(argv)
    try:
        check_tolerance(args.tolerance, args.severity, "argument --tolerance:")
    except ValueError as error:
        parser.error(str(error))
    args.agents = [str(agent(str(a), args)) for a in args.agents]
    if len(set(args.agents)) != len(args.agents):
        parser.error(f"argument --agents: an agent is named twice ({', '.join(args.agents)})")
    return args


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    parser = build_parser()
    args = parse_args(argv, parser)
    out = cli.open_output(parser, args, "intersection", FILES, argv)
    seeds = list(range(args.seed, args.seed + args.episodes))
    jobs = [(spec, seeds[i : i + CHUNK], args) for spec in args.agents for i in range(0, len(seeds), CHUNK)]
    with out:
        t0 = time.perf_counter()
        chunks = run_sweep(run_chunk, jobs, workers=args.workers, desc=args.env, store=out.store)
        rows: dict[str, list[dict[str, Any]]] = {spec: [] for spec in args.agents}
        for (spec, _, _), chunk in zip(jobs, chunks, strict=True):
            rows[spec] += chunk
        wall = time.perf_counter() - t0
        summary = [summarise(spec, rows[spec], args) for spec in args.agents]
        with open(out.dir / "intersection.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(summary[0]))
            writer.writeheader()
            writer.writerows(summary)
        fields = ["agent", "seed", "steps", "time_s", "collision", "ego_into_vehicle", "vehicle_into_ego",
                  "goal", "timeout", "risk_mean", "fallbacks"]  # fmt: skip
        with open(out.dir / "intersection_episodes.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=[*fields, "solve_ms_median"])
            writer.writeheader()
            for spec in args.agents:
                for r in rows[spec]:
                    solve = r["solve_times"]
                    median = float(np.median(solve)) * 1e3 if solve.size else ""
                    writer.writerow({k: r[k] for k in fields} | {"solve_ms_median": median})
        text = markdown(summary, args, wall, out.command_line.strip())
        (out.dir / "intersection.md").write_text(text)
    print(text)
    return summary


if __name__ == "__main__":
    main()
