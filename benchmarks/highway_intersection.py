"""Our agents in highway-env: RMPC and SMPC drive ``intersection-v1`` against highway-env's own IDM.

    python -m benchmarks.highway_intersection --episodes 2 --agents rmpc,idm     # a quick look
    python -m benchmarks.highway_intersection --agents rmpc,smpc,idm,rmpc:3 --out docs/results/highway

Each agent drives the controlled vehicle of ``intersection-v1`` (:data:`INTERSECTION_CONFIG`: the
kinematic vehicle with continuous actions, T = 0.5 s, highway-env's traffic, the left turn to
``"o1"``, 13 s) over the same seeded episodes (seeds 0..E-1; the traffic then reacts to the ego):

- ``rmpc``: :class:`agents.RMPC` (worst case, exact box form) through :class:`IntersectionAdapter`;
- ``smpc``: :class:`agents.SMPC` (exact risk) through the adapter;
- ``idm``: :class:`IDMEgo`, highway-env's ``IDMVehicle`` on the same route (its reference driver);
- ``rmpc:3``, ``smpc:3``: the adapter planning against the 3 most conflicting vehicles and applying
  the slowest plan (``IntersectionAdapter(objects=3)``, a heuristic beyond the paper); the solve
  time per step is then the sum of the 3 solves.

The risk of every step is scored by :class:`RiskCostWrapper` (exact estimator) between the ego and
every other vehicle, with the agents' scenario (uncertainty preset, severity, the adapter's 2 m
discs). Reported per agent: collision rate (Wilson 95 % interval) and how many of the collisions
were with the vehicle the MPC planned against, goal rate (arrived on the road to ``"o1"``),
timeouts, mean and 95th percentile of the per-step risk, the share of steps above epsilon, the
MPC's solve time per step (median / p95 / max) and its failed solves. Outputs in ``--out``:
``intersection.md``, ``intersection.csv`` (summary) and ``intersection_episodes.csv``.
"""

from __future__ import annotations

import argparse
import csv
import functools
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from benchmarks import cli
from benchmarks.sampled import wilson
from risk_env.scenario import SEVERITY_NAMES, UNCERTAINTY_PRESETS
from risk_env.severity import check_tolerance

AGENTS = ("rmpc", "smpc", "idm")
LABELS = {"rmpc": "RMPC (worst case)", "smpc": "SMPC (exact)", "idm": "highway-env IDM"}


def label(spec: str) -> str:
    """``"rmpc:3"`` -> ``"RMPC (worst case), 3 objects"``."""
    name, _, objects = spec.partition(":")
    return LABELS[name] + (f", {objects} objects" if objects and objects != "1" else "")


CRASH_MATCH = 6.0
"""A collision counts as with the planned-for object when the vehicle hit is within this distance
[m] of where that object was predicted to be after the last step."""


def make_driver(spec: str, env: Any, args: argparse.Namespace) -> Any:
    """The driver ``spec`` = ``name[:objects]`` for ``env`` (name one of :data:`AGENTS`)."""
    from agents import RMPC, SMPC
    from risk_env.highway import IDMEgo, IntersectionAdapter

    name, _, objects = spec.partition(":")
    if name == "idm":
        return IDMEgo(env)
    factory = RMPC if name == "rmpc" else functools.partial(SMPC, risk="exact")
    return IntersectionAdapter(
        env,
        factory,
        uncertainty=args.uncertainty,
        risk_tolerance=args.tolerance,
        severity=args.severity,
        objects=int(objects or 1),
    )


def run_episode(driver: Any, env: Any, seed: int) -> dict[str, Any]:
    """One episode; returns its row (metrics and per-step arrays)."""
    from risk_env.dynamics import unicycle_step
    from risk_env.highway.adapter import reached
    from risk_env.ops import NUMPY

    obs, info = env.reset(seed=seed)
    if hasattr(driver, "reset"):
        driver.reset()
    base = env.unwrapped
    risks, times = [], []
    predicted_object = None
    done = False
    while not done:
        action, _ = driver.predict(obs)
        if getattr(driver, "last_solve", None) is not None:
            times.append(driver.last_solve_time)
        obj = getattr(driver, "last_object", None)
        if obj is not None:
            predicted_object = np.array(unicycle_step(*obj, env.scenario.dt, NUMPY)[:2], dtype=float)
        obs, _, terminated, truncated, info = env.step(action)
        risks.append(info["risk"])
        done = terminated or truncated
    ego = base.vehicle
    crashed = bool(ego.crashed)
    with_object = False
    if crashed and predicted_object is not None:
        hit = [v for v in base.road.vehicles if v is not ego and v.crashed]
        if hit:
            nearest = min(hit, key=lambda v: float(np.hypot(*(v.position - ego.position))))
            with_object = bool(np.hypot(*(nearest.position - predicted_object)) < CRASH_MATCH)
    goal = reached(env, driver.destination)
    risks = np.array(risks)
    return {
        "seed": seed,
        "steps": len(risks),
        "time_s": float(base.time),
        "collision": crashed,
        "collision_with_object": with_object,
        "goal": goal,
        "timeout": not crashed and not goal,
        "risk_mean": float(risks.mean()) if len(risks) else 0.0,
        "risk_max": float(risks.max()) if len(risks) else 0.0,
        "risk_steps": risks,
        "violations": int(np.sum(risks > env.scenario.risk_tolerance * (1 + 1e-6) + 1e-9)),
        "solve_times": np.array(times),
        "failed_solves": int(getattr(driver, "failures", 0)),
    }


def summarise(name: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """One agent's row of the summary table."""
    n = len(rows)
    collisions = sum(r["collision"] for r in rows)
    low, high = wilson(collisions, n)
    risk = np.concatenate([r["risk_steps"] for r in rows]) if rows else np.zeros(0)
    solve = np.concatenate([r["solve_times"] for r in rows]) * 1e3 if rows else np.zeros(0)
    goals = [r["time_s"] for r in rows if r["goal"]]
    return {
        "agent": name,
        "label": label(name),
        "episodes": n,
        "collision_rate": collisions / n,
        "collision_ci_low": low,
        "collision_ci_high": high,
        "collisions_with_object": sum(r["collision_with_object"] for r in rows),
        "goal_rate": sum(r["goal"] for r in rows) / n,
        "timeout_rate": sum(r["timeout"] for r in rows) / n,
        "time_to_goal_s": float(np.mean(goals)) if goals else float("nan"),
        "risk_mean": float(risk.mean()) if risk.size else 0.0,
        "risk_p95": float(np.percentile(risk, 95)) if risk.size else 0.0,
        "violation_rate": float(np.mean(risk > rows[0]["epsilon"] * (1 + 1e-6) + 1e-9)) if risk.size else 0.0,
        "solve_ms_median": float(np.median(solve)) if solve.size else float("nan"),
        "solve_ms_p95": float(np.percentile(solve, 95)) if solve.size else float("nan"),
        "solve_ms_max": float(np.max(solve)) if solve.size else float("nan"),
        "failed_solves": sum(r["failed_solves"] for r in rows),
        "steps": int(risk.size),
    }


def _fmt(x: Any, digits: int = 1) -> str:
    if isinstance(x, float):
        return "-" if np.isnan(x) else f"{x:.{digits}f}"
    return str(x)


def markdown(summary: list[dict[str, Any]], args: argparse.Namespace, wall: float) -> str:
    """The summary as a Markdown table with its settings."""
    head = (
        "| agent | episodes | collisions [95% CI] | with the planned-for object | goal | timeout |"
        " time to goal [s] | risk mean | risk p95 | steps > eps | solve ms median / p95 / max |"
        " failed solves |"
    )
    lines = [
        f"intersection-v1 (INTERSECTION_CONFIG), seeds {args.seed}..{args.seed + args.episodes - 1},"
        f" uncertainty {args.uncertainty}, severity {args.severity}, epsilon {args.tolerance:g};"
        f" risk scored by RiskCostWrapper (exact). Wall time {wall:.0f} s.",
        "",
        head,
        "| " + " | ".join(["---"] * 12) + " |",
    ]
    for s in summary:
        solve = (
            "-"
            if np.isnan(s["solve_ms_median"])
            else f"{s['solve_ms_median']:.1f} / {s['solve_ms_p95']:.1f} / {s['solve_ms_max']:.0f}"
        )
        idm = s["agent"] == "idm"
        with_object = "-" if idm else str(s["collisions_with_object"])
        lines.append(
            f"| {s['label']} | {s['episodes']} | {100 * s['collision_rate']:.0f}%"
            f" [{100 * s['collision_ci_low']:.0f}, {100 * s['collision_ci_high']:.0f}] | {with_object} |"
            f" {100 * s['goal_rate']:.0f}% | {100 * s['timeout_rate']:.0f}% | {_fmt(s['time_to_goal_s'])} |"
            f" {s['risk_mean']:.3g} | {s['risk_p95']:.3g} | {100 * s['violation_rate']:.1f}% | {solve} |"
            f" {'-' if idm else s['failed_solves']} |"
        )
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.highway_intersection``."""
    parser = cli.parser("highway_intersection", __doc__)
    parser.add_argument("--episodes", type=int, default=50, help="seeded episodes per agent")
    parser.add_argument("--seed", type=int, default=0, help="first seed")
    parser.add_argument(
        "--agents",
        default=",".join(AGENTS),
        help=f"comma list of {', '.join(AGENTS)}; NAME:K (e.g. rmpc:3) plans against the K most"
        " conflicting vehicles",
    )
    parser.add_argument(
        "--uncertainty",
        choices=UNCERTAINTY_PRESETS,
        default="low",
        help="Table I level (per 0.5 s step)",
    )
    parser.add_argument("--severity", choices=SEVERITY_NAMES, default="paper", help="severity model")
    parser.add_argument("--tolerance", type=float, default=500.0, help="epsilon [units of the severity]")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("results/highway"),
        help="output folder for intersection.md and the CSVs; the committed ones are in docs/results/highway",
    )
    return parser


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.agents = [a.strip() for a in args.agents.split(",") if a.strip()]
    unknown = [
        a
        for a in args.agents
        if a.partition(":")[0] not in AGENTS
        or not (a.partition(":")[2] or "1").isdigit()
        or a.startswith("idm:")
    ]
    if unknown:
        parser.error(f"unknown agent(s) {unknown}; expected some of {AGENTS}")
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    try:
        check_tolerance(args.tolerance, args.severity, "--tolerance")
    except ValueError as error:
        parser.error(str(error))
    return args


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    args = parse_args(argv)
    from risk_env.highway import RiskCostWrapper, make_intersection_env
    from risk_env.highway.adapter import ADAPTER_DEFAULTS

    radii = {k: ADAPTER_DEFAULTS[k] for k in ("ego_radius", "object_radius")}
    t0 = time.perf_counter()
    rows: dict[str, list[dict[str, Any]]] = {}
    bar = tqdm(total=len(args.agents) * args.episodes, desc="intersection-v1", unit="episode")
    for name in args.agents:
        env = RiskCostWrapper(
            make_intersection_env(),
            uncertainty=args.uncertainty,
            estimator="exact",
            risk_tolerance=args.tolerance,
            severity=args.severity,
            **radii,
        )
        driver = make_driver(name, env, args)
        rows[name] = []
        for seed in range(args.seed, args.seed + args.episodes):
            row = run_episode(driver, env, seed)
            row.update(agent=name, epsilon=args.tolerance)
            rows[name].append(row)
            bar.update(1)
            bar.set_postfix(agent=name, collisions=sum(r["collision"] for r in rows[name]))
        env.close()
    bar.close()
    wall = time.perf_counter() - t0
    summary = [summarise(name, rows[name]) for name in args.agents]

    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "intersection.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(summary[0]))
        writer.writeheader()
        writer.writerows(summary)
    episode_fields = [
        "agent", "seed", "steps", "time_s", "collision", "collision_with_object", "goal", "timeout",
        "risk_mean", "risk_max", "violations", "failed_solves", "solve_ms_median",
    ]  # fmt: skip
    with open(args.out / "intersection_episodes.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=episode_fields)
        writer.writeheader()
        for name in args.agents:
            for r in rows[name]:
                solve = r["solve_times"]
                writer.writerow(
                    {k: r[k] for k in episode_fields if k in r}
                    | {"solve_ms_median": float(np.median(solve)) * 1e3 if solve.size else ""}
                )
    text = markdown(summary, args, wall)
    (args.out / "intersection.md").write_text(text)
    print(text)
    return summary


if __name__ == "__main__":
    main()
