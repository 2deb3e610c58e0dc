"""How often the junction gate opens, against what going at once would have done.

    python -m benchmarks.highway_gate --episodes 10 --out results/highway/gate
    python -m benchmarks.highway_gate --episodes 10 --interval split_yield --given-ego --clearance 2

Each episode (seeds S..S+E-1, ``intersection-v2`` with
:data:`~risk_env.highway.adapter.INTERSECTION_CONFIG`) has the ego wait at the stop line for the
whole episode (the hindsight reference's driver told never to go,
:func:`benchmarks.highway_hindsight.scheduled_vehicle`). At every step at which its stop is within
:data:`AT_LINE` metres, it asks

- **the gate** (:class:`~risk_env.highway.gate.JunctionGate`, built as the adapter builds it, on
  ``--predictor``, with ``--clearance``, ``--margin`` and, with ``--given-ego``, the others
  predicted given that the ego goes) whether it would let the ego go now, and
- **the future**: a copy of the simulator (the traffic's random draws included) in which the ego
  goes now and drives on to the episode's end (the env's 13 s, whatever ``--duration``), or with
  ``--lookahead`` for that many seconds whatever the episode's length (highway-env's IDM on its
  route, never yielding; with ``--future-ego planner`` at the planners' acceleration and reference
  speed, which the gate assumes, instead of highway-env's traffic's): whether it has no collision
  (*free*), and whether it reaches the goal without one (*through*; a free ego may also stand in
  the junction, locked with a crossing car, or behind a wreck).

``gate.md`` has, per configuration: the steps judged, the free and the through ones, the steps the
gate opened, and the openings at a step where going collided (*bad*: a gate that is right never
has one); a copy cut at the episode's end judges its last steps over less time, so that
``--lookahead`` (10 s or more: the ego crosses in about 5) is the fairer judge;
``gate.csv`` has every judged step. A gate that opens at few of the free steps keeps the ego
waiting where it could have gone: the planners' deadlocks (see the highway docs).
"""

from __future__ import annotations

import argparse
import copy
import csv
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cli
from benchmarks.highway_agents import add_interval_option
from benchmarks.sampled_rows import wilson
from benchmarks.sweep import run_sweep

AT_LINE = 10.0
"""The gate is asked while the ego's stop is at most this far [m] ahead of it."""
DESTINATION = "o1"
"""The ego's destination: ``intersection-v2``'s (a left turn)."""
FILES = ("gate.csv", "gate.md")
FIELDS = ("seed", "step", "time_s", "free", "through", "open", "slack_s")
FUTURE_EGOS = {
    "idm": "highway-env's IDM, with its traffic's acceleration, up to the lanes' limit",
    "planner": "an IDM with the acceleration and the speed the gate assumes for the ego (the planners')",
}
"""How the table's header names each ``--future-ego``."""


JUDGED = {
    "boxes": "truncation boxes",
    "footprint": "mean car",
    "near": "truncation boxes over the MPCs' 3 s horizon and mean car after",
    "stretch": "stretch of its route over the MPCs' 3 s horizon and mean car after",
    "tracks": "tracks along the stretch of its route, each a share of its weight",
    "rollout": "part in the scene rolled out with the ego going (lanes.rollout)",
}
"""How the table's header names each judge's view of a mode."""


def judge_episode(seed: int, args: Any) -> list[dict[str, Any]]:
    """The judged steps of episode ``seed`` (see the module): one row each."""
    from benchmarks.highway_agents import built_predictor
    from benchmarks.highway_hindsight import outcome, scheduled_vehicle
    from risk_env.highway import highway_scenario, make_intersection_env, vehicle_measurement
    from risk_env.highway.adapter import ADAPTER_DEFAULTS
    from risk_env.highway.gate import make_gate
    from risk_env.highway.gate_judge import GateSettings
    from risk_env.highway.idm import put_ego
    from risk_env.highway.route import RoutePath

    env = make_intersection_env()
    env.reset(seed=seed)
    base = env.unwrapped
    put_ego(base, scheduled_vehicle(base, math.inf, DESTINATION))
    predictor = built_predictor(args.predictor, env, switches=args.interval)
    scenario = highway_scenario(env, "low", **ADAPTER_DEFAULTS)  # the adapter's
    settings = GateSettings(
        clearance=args.clearance,
        margin=args.margin,
        judge=args.judge,
        tolerance=args.tolerance,
        given_ego=args.given_ego,
    )
    gate, _ = make_gate(settings, predictor, scenario, env)
    route = RoutePath.of_vehicle(base.road.network, base.vehicle, DESTINATION)
    gate.reset(route, scenario)
    # the ego that goes at once: our ego's acceleration and speed, as the gate judges it, or highway-env's
    future_driver = (gate.accel, gate.speed_cap) if args.future_ego == "planner" else (None, None)
    rows: list[dict[str, Any]] = []
    action = np.zeros(2, dtype=np.float32)
    for step in range(int(round(args.duration / gate.dt))):
        ego = base.vehicle
        progress = route.progress(0, *ego.position)  # it waits on its route's first lane
        if gate.span[0] - gate.half_length - progress <= AT_LINE:
            vehicles = [v for v in base.road.vehicles if v is not ego]
            others = np.array([vehicle_measurement(v) for v in vehicles])
            # what highway-env's observe_intentions shows: the unit vector to each one's destination
            signals = [v.destination_direction for v in vehicles] if args.signals else None
            gate.committed, gate.last = False, type(gate.last)(False, False)
            verdict = gate.decide(progress, float(ego.speed), others, signals)
            future = copy.deepcopy(base)
            put_ego(future, scheduled_vehicle(future, 0, DESTINATION, *future_driver))
            if args.lookahead is not None:
                future.config["duration"] = float(base.time) + args.lookahead
            crashed, goal = outcome(future, DESTINATION)
            rows.append(
                {
                    "seed": seed,
                    "step": step,
                    "time_s": float(base.time),
                    "free": not crashed,
                    "through": goal and not crashed,
                    "open": not verdict.closed,
                    "slack_s": float(verdict.slack),
                }
            )
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    env.close()
    return rows


def run_chunk(job: tuple[list[int], Any]) -> list[dict[str, Any]]:
    """The rows of the episodes ``seeds`` (a pool job)."""
    seeds, args = job
    return [row for seed in seeds for row in judge_episode(seed, args)]


def markdown(rows: list[dict[str, Any]], args: Any, command: str, wall: float) -> str:
    """``gate.md``: the command, the set-up and the table."""
    judged = len(rows)
    free = sum(r["free"] for r in rows)
    opened = sum(r["open"] for r in rows)
    good = sum(r["open"] and r["free"] for r in rows)
    through = sum(r["through"] for r in rows)
    passed = sum(r["open"] and r["through"] for r in rows)
    bad = sum(r["open"] and not r["free"] for r in rows)

    def rate(k: int, n: int) -> str:
        if n == 0:
            return f"{k} (of none)"
        lo, hi = wilson(k, n)
        return f"{k} ({100 * k / max(n, 1):.1f}% [{100 * lo:.1f}, {100 * hi:.1f}])"

    switches = ", ".join(args.interval) or "none"
    closing = "at any conflict" if args.tolerance == 0 else f"above a conflict chance of {args.tolerance:g}"
    signals = ", turn signals read" if args.signals else ""
    if args.judge == "rollout":  # no clearance, margin or tolerance: the rollout's own numbers
        judged_how = (
            f"the scene rolled out with the ego going, the gate open if the ego comes through{signals}"
        )
    else:
        judged_how = (
            f"clearance {args.clearance:g} m, margin {args.margin:g} s, others predicted"
            f" {'given that the ego goes' if args.given_ego else 'with the ego braking'}{signals};"
            f" each mode judged by its {JUDGED[args.judge]}, the gate closing {closing}"
        )
    return "\n".join(
        [
            f"`{command}`",
            "",
            f"intersection-v2, seeds {args.seed}..{args.seed + args.episodes - 1}, {args.duration:g} s"
            f"{'' if args.lookahead is None else f', going at once judged over {args.lookahead:g} s'};"
            f" the ego waits at the line; predictor {args.predictor} (interval switches: {switches}),"
            f" {judged_how}. Going at once: {FUTURE_EGOS[args.future_ego]}."
            " Wall time"
            f" {wall:.0f} s. Rates: of the steps judged (free, opened) or of the free steps (opened"
            " where free) or of the through steps (opened where through) [Wilson 95 %].",
            "",
            "| steps judged | free (going at once collision-free) | through (going at once reaches the"
            " goal, collision-free) | gate open | open where free | open where through | open where"
            " going collided |",
            "| --- | --- | --- | --- | --- | --- | --- |",
            f"| {judged} | {rate(free, judged)} | {rate(through, judged)} | {rate(opened, judged)} |"
            f" {rate(good, free)} | {rate(passed, through)} | {bad} |",
            "",
        ]
    )


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.highway_gate``."""
    from risk_env.highway.gate_judge import JUDGES, GateSettings
    from risk_env.highway.predictors import HIGHWAY_PREDICTORS

    defaults = GateSettings()
    parser = cli.parser("highway_gate", __doc__)
    parser.add_argument("--episodes", type=cli.positive_int, default=10, help="seeded episodes")
    parser.add_argument("--seed", type=cli.nonnegative_int, default=0, help="first seed")
    parser.add_argument(
        "--duration", type=cli.positive_float, default=13.0, help="episode length [s] (highway-env's 13)"
    )
    parser.add_argument(
        "--lookahead",
        type=cli.positive_float,
        default=None,
        help="judge going at once over this many seconds [s] from each step, whatever the episode's"
        " length (default: to the episode's end)",
    )
    parser.add_argument("--predictor", choices=HIGHWAY_PREDICTORS, default="lane+interval", help="the gate's")
    add_interval_option(parser)
    parser.add_argument(
        "--clearance",
        type=cli.positive_float,
        default=defaults.clearance,
        help="distance [m] from the ego's path within which a box is in conflict (at most the discs' 4 m)",
    )
    parser.add_argument(
        "--margin",
        type=cli.nonnegative_float,
        default=defaults.margin,
        help="time [s] to spare at each point",
    )
    parser.add_argument(
        "--judge",
        choices=JUDGES,
        default=defaults.judge,
        help="a mode occupies what its truncation boxes hold, or its mean car (risk_env.highway.gate_judge)",
    )
    parser.add_argument(
        "--tolerance",
        type=cli.unit_interval,
        default=defaults.tolerance,
        help="the chance of a conflict the gate accepts (0: none; summed over each vehicle's modes)",
    )
    parser.add_argument(
        "--signals",
        action="store_true",
        help="the lane predictors read each vehicle's turn signal (highway-env's observe_intentions)",
    )
    parser.add_argument(
        "--given-ego",
        action=argparse.BooleanOptionalAction,
        default=defaults.given_ego,
        help="predict the others given that the ego goes (lane+interval only; else with the ego braking)",
    )
    parser.add_argument(
        "--future-ego",
        choices=("idm", "planner"),
        default="idm",
        help="who drives the ego that goes at once: highway-env's IDM (its traffic's acceleration, up to"
        " the lanes' limit), or an IDM with the planners' acceleration and reference speed, as the gate"
        " judges the ego",
    )
    parser.add_argument(
        "--workers", type=cli.positive_int, default=None, help="processes (default: all cores)"
    )
    cli.add_output_options(parser, Path("results/highway/gate"), "output folder", resume=True)
    return parser


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.predictor != "lane+interval" and (args.interval or args.given_ego):
        parser.error("--interval and --given-ego need --predictor lane+interval")
    if args.predictor == "constant" and args.signals:
        parser.error("--signals needs a lane predictor (--predictor lane or lane+interval)")
    out = cli.open_output(parser, args, "gate", FILES, argv)
    jobs = [([seed], args) for seed in range(args.seed, args.seed + args.episodes)]
    with out:
        t0 = time.perf_counter()
        chunks = run_sweep(run_chunk, jobs, workers=args.workers, desc="gate episodes", store=out.store)
        rows = [row for chunk in chunks for row in chunk]
        wall = time.perf_counter() - t0
        with open(out.dir / "gate.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(FIELDS))
            writer.writeheader()
            writer.writerows(rows)
        text = markdown(rows, args, out.command_line.strip(), wall)
        (out.dir / "gate.md").write_text(text)
        print(text)
    return rows


if __name__ == "__main__":
    main()
