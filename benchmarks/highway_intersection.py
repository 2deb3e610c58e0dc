"""Our agents in highway-env: RMPC and SMPC drive ``intersection-v2`` against highway-env's IDM.

    python -m benchmarks.highway_intersection --episodes 4 --agents rmpc,idm     # a quick look
    python -m benchmarks.highway_intersection --episodes 200 --max-solve-time inf \\
        --agents rmpc,smpc,smpc:probability:0.01,idm --out results/highway
    python -m benchmarks.highway_intersection --episodes 200 --duration 40 --max-solve-time inf \\
        --agents rmpc,smpc,idm --out results/highway/40s
    python -m benchmarks.highway_intersection --episodes 20 --predictor lane,constant \\
        --agents rmpc,smpc:budget=0.02 --initial-vehicles 5 --spawn-probability 0.3 --workers 1

Each agent drives the controlled vehicle of ``intersection-v2`` (``--env intersection-v1``
selectable; :data:`~risk_env.highway.adapter.INTERSECTION_CONFIG`: the kinematic vehicle with
continuous actions, T = 0.5 s, highway-env's traffic, the left turn to ``"o1"``) over the same
seeded episodes (seeds S..S+E-1; the traffic then reacts to the ego). highway-env's own
``duration`` (13 s), ``spawn_probability`` (0.6) and ``initial_vehicle_count`` (10) are set by
``--duration``, ``--spawn-probability`` and ``--initial-vehicles``. Agents (``--agents``, named as
in every command, :mod:`benchmarks.agent_names`; at the intersection as
:mod:`benchmarks.highway_agents` reads them):

- ``rmpc[:RISK]``: :class:`agents.RMPC` (default: worst case) through :class:`IntersectionAdapter`
  with ``--slots`` object slots (default 5): one solve plans against every observed vehicle, the
  nearest first, up to the slot count, and against every predicted mode of weight at least
  ``--mode-threshold``;
- ``smpc[:RISK]``: :class:`agents.SMPC` (default: exact risk) with ``--severity`` (probability) and
  an episode risk budget B = ``--budget`` (0.05: a 5 % chance of a collision per episode), no
  per-step bound; ``smpc:budget=0.02`` another budget; ``smpc:probability:0.01`` the per-step
  bound alone (a collision chance of at most 1 % per step under the prediction);
- ``idm``: :class:`IDMEgo`, highway-env's ``IDMVehicle`` on the same route (its reference driver).
- ``hindsight``: :class:`~benchmarks.highway_hindsight.HindsightEgo`, the first wait-then-go
  schedule that arrives unharmed, found in the episode's own future (an upper reference).

The MPCs plan with each predictor of ``--predictor`` (``lane``: the routes along highway-env's
lanes; ``constant``: the paper's; ``lane,constant`` runs each MPC with both, on the same seeds),
the IDM once. Reported per agent (:mod:`benchmarks.highway_tables`): collisions by kind
(:mod:`benchmarks.highway_episodes`), goal rate, timeouts and deadlocks, with Wilson intervals;
time to goal; fallback steps as a share of all steps; the realised episode risk of an SMPC with a
budget against B; solve time per step as CPU and wall time (median / p95 / max; the steps that
built a new size of the MPC's problem are counted apart, not timed); and the risk
scored by :class:`RiskCostWrapper` (exact, ``--severity``, the first predictor). Episodes run in a
process pool (:mod:`benchmarks.sweep`, ``--workers``). Outputs in ``--out``: ``intersection.md``,
``intersection.csv`` (summary) and ``intersection_episodes.csv``, one output set
(:mod:`benchmarks.output`; ``--resume`` goes on after an interruption). The safety-progress
frontier of a set of budgets is :mod:`benchmarks.highway_frontier`.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from benchmarks import cli
from benchmarks.agent_names import REFERENCES
from benchmarks.highway_agents import (
    DEFAULT_BUDGET,
    KINDS,
    add_gate_options,
    add_interval_option,
    check_budget,
    resolve,
)
from benchmarks.highway_episodes import ENV_DEFAULTS, crash_kind, run_chunk
from benchmarks.highway_tables import markdown, summarise, write_csvs
from benchmarks.sweep import run_sweep
from risk_env.highway.adapter import ADAPTER_DEFAULTS
from risk_env.prediction.predictors import PREDICTOR_NAMES
from risk_env.scenario.parts import Ego
from risk_env.scenario.scenario import SEVERITY_NAMES, UNCERTAINTY_PRESETS

FILES = ("intersection.csv", "intersection.md", "intersection_episodes.csv")
"""The files a run writes in ``--out``."""
ENVS = ("intersection-v2", "intersection-v1")
CHUNK = 5
"""Episodes per pool job (each process keeps its env and agents between jobs)."""
__all__ = ["crash_kind", "run", "add_options", "parse_args", "main"]


class Gone(argparse.Action):
    """A flag of an earlier version whose meaning moved elsewhere: an error saying where."""

    def __init__(self, option_strings: list[str], dest: str, where: str = "", **kwargs: Any) -> None:
        super().__init__(option_strings, dest, help=argparse.SUPPRESS, **kwargs)
        self.where = where

    def __call__(self, parser: Any, namespace: Any, values: Any, option_string: str | None = None) -> None:
        parser.error(f"argument {option_string}: {self.where}")


def add_options(parser: argparse.ArgumentParser, agents: str, predictors: str, out: Path) -> None:
    """The options of the intersection commands, with the defaults ``agents``, ``predictors`` and
    ``out``."""
    from agents.mpc.nlp.risk_budget import BUDGET_SHARE
    from agents.mpc.objects import MODE_THRESHOLD

    parser.add_argument("--episodes", type=cli.positive_int, default=200, help="seeded episodes per agent")
    parser.add_argument("--seed", type=cli.nonnegative_int, default=0, help="first seed")
    parser.add_argument("--env", choices=ENVS, default=ENVS[0], help="highway-env intersection")
    parser.add_argument(
        "--agents",
        type=cli.agents_list(KINDS),
        default=agents,
        help="comma list of rmpc[:RISK], smpc[:RISK][:SEVERITY:TOLERANCE][:budget=B], idm, hindsight",
    )
    parser.add_argument(
        "--predictor",
        type=cli.choices_list(PREDICTOR_NAMES, "predictor"),
        default=predictors,
        help="the MPCs' predictor, or a comma list (each MPC runs with each; the first scores the risk)",
    )
    parser.add_argument("--duration", type=cli.positive_float, default=ENV_DEFAULTS["duration"],
                        help="episode length [s] (highway-env's duration)")  # fmt: skip
    parser.add_argument(
        "--spawn-probability",
        type=cli.unit_interval_closed,
        default=ENV_DEFAULTS["spawn_probability"],
        help="chance of a new vehicle per step (highway-env's spawn_probability)",
    )
    parser.add_argument(
        "--initial-vehicles",
        type=cli.nonnegative_int,
        default=int(ENV_DEFAULTS["initial_vehicle_count"]),
        help="vehicles at the start (highway-env's initial_vehicle_count)",
    )
    parser.add_argument(
        "--budget",
        type=cli.nonnegative_float,
        default=DEFAULT_BUDGET,
        help="episode risk budget B of an SMPC named without a tolerance or budget [--severity's unit]",
    )
    parser.add_argument(
        "--budget-share",
        type=cli.fraction,
        default=BUDGET_SHARE,
        help="share of what is left of the budget a step may spend (the SMPC's budget_share)",
    )
    parser.add_argument(
        "--mode-threshold",
        type=cli.unit_interval_closed,
        default=MODE_THRESHOLD,
        help="w_min: the RMPC plans against every predicted mode of at least this weight",
    )
    parser.add_argument(
        "--corridor",
        type=cli.positive_or_inf,
        default=ADAPTER_DEFAULTS["corridor"],
        help="half width [m] around the lane's centreline that the MPCs' planned centre keeps within"
        " (inf: none, the ego may leave its lane)",
    )
    parser.add_argument(
        "--object-radius",
        type=cli.positive_float,
        default=ADAPTER_DEFAULTS["object_radius"],
        help="radius [m] of the other vehicles' discs in the MPCs' rows (the score keeps 2 m): two 2 m"
        " discs make a car passing in the lane beside, 4 m away, a collision",
    )
    parser.add_argument(
        "--v-ref",
        type=cli.positive_float,
        default=ADAPTER_DEFAULTS["v_ref"],
        help="the MPCs' reference speed v_ref [m/s] (also the gate's crossing speed; v_max rises to it)",
    )
    parser.add_argument(
        "--ego-accel",
        type=cli.positive_float,
        default=Ego.accel_max,
        help="the ego's largest acceleration and braking in the MPCs and the gate [m/s^2]",
    )
    parser.add_argument(
        "--car-turning",
        action="store_true",
        help="the MPCs turn only while they move, within highway-env's car's turning circle at full"
        " lock: |omega| <= kappa v (Ego.curvature_max); off: the paper's unicycle, which turns standing",
    )
    parser.add_argument(
        "--restart-standing",
        action="store_true",
        help="where the ego and its last plan stand, the MPCs also solve from cold and keep the cheaper"
        " plan (restart_standing)",
    )
    parser.add_argument(
        "--car-discs",
        type=cli.positive_int,
        default=1,
        help="n: the MPCs see the ego and every vehicle as n discs along its length covering highway-env's"
        " 5 x 2 m car (radius sqrt((5/2n)^2 + 1); 1: one disc of --object-radius, the ego's 2 m)",
    )
    parser.add_argument(
        "--lane-pieces",
        type=cli.positive_int,
        default=1,
        help="P: the MPCs' lane predictor splits each route's reachable stretch into P bands, one mode"
        " each (smaller boxes on curves; the risk is scored with P = 1)",
    )
    add_interval_option(parser)
    add_gate_options(parser)
    parser.add_argument(
        "--gate",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the junction gate: the MPCs wait at a virtual stop line unless they can cross the"
        " junction before the predicted traffic reaches their path (risk_env.highway.gate)",
    )
    parser.add_argument("--slots", type=cli.positive_int, default=5, help="the MPC's object slots")
    parser.add_argument("--uncertainty", choices=UNCERTAINTY_PRESETS, default="low", help="Table I level")
    parser.add_argument(
        "--severity",
        choices=SEVERITY_NAMES,
        default="probability",
        help="the SMPCs' and the score's severity",
    )
    parser.add_argument(
        "--tolerance",
        action=Gone,
        where="gone: name the SMPC's per-step bound in the agent, e.g. --agents smpc:probability:0.01",
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
    cli.add_output_options(parser, out, "output folder", resume=True)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.highway_intersection``."""
    parser = cli.parser("highway_intersection", __doc__)
    add_options(parser, "rmpc,smpc,idm", PREDICTOR_NAMES[1], Path("results/highway"))
    return parser


def parse_args(
    argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None
) -> argparse.Namespace:
    """The options, checked (every bad value an error naming its flag, before any episode)."""
    parser = parser or build_parser()
    args = parser.parse_args(argv)
    try:
        check_budget(args.budget, args.severity, "argument --budget: the budget")
    except ValueError as error:
        parser.error(str(error))
    check_duration(parser, args.duration, "--duration")
    if len(set(args.predictor)) != len(args.predictor):
        parser.error(f"argument --predictor: a predictor is named twice ({','.join(args.predictor)})")
    try:
        agents = [resolve(a, args.severity, args.budget) for a in args.agents]
    except ValueError as error:
        parser.error(f"argument --agents: {error}")
    args.agents = [a.name for a in agents]
    if len(set(args.agents)) != len(args.agents):
        parser.error(f"argument --agents: an agent is named twice ({', '.join(args.agents)})")
    check_rollout(parser, args)
    return args


def check_rollout(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """A usage error when the gate rolls the scene out (``--gate-judge rollout``, ``--gate-passage``)
    for an MPC planning with a predictor other than ``lane+interval`` (the rollout's)."""
    flags = [("--gate-judge rollout", args.gate_judge == "rollout"), ("--gate-passage", args.gate_passage)]
    used = [flag for flag, on in flags if on and args.gate]
    planners = [a for a in args.agents if a not in REFERENCES]
    other = [p for p in args.predictor if p != "lane+interval"]
    if used and planners and other:
        parser.error(f"argument {used[0]}: needs --predictor lane+interval (the rollout's), got {other[0]}")


def check_duration(parser: argparse.ArgumentParser, duration: float, flag: str) -> None:
    """A usage error naming ``flag`` unless ``duration`` [s] holds at least one step."""
    from risk_env.highway.adapter import INTERSECTION_CONFIG

    step = 1.0 / INTERSECTION_CONFIG["policy_frequency"]
    if duration < step:
        parser.error(f"argument {flag}: {duration:g} s is shorter than one step ({step:g} s)")


def plan_runs(agents: list[str], predictors: list[str]) -> list[tuple[str, str]]:
    """The runs ``(agent, predictor)`` of a command: each MPC with each predictor, in the order
    given, the IDM once (predictor ``""``)."""
    return [(name, p) for name in agents for p in (predictors if name not in REFERENCES else [""])]


def run(args: argparse.Namespace, out: Any) -> tuple[list[dict[str, Any]], list[dict[str, Any]], float]:
    """Every agent's episodes (each MPC with each predictor, the IDM once) in the output set
    ``out``'s chunk store: the summary rows, the episode rows and the wall time [s]."""
    seeds = list(range(args.seed, args.seed + args.episodes))
    runs = plan_runs(args.agents, args.predictor)
    jobs = [(name, p, seeds[i : i + CHUNK], args) for name, p in runs for i in range(0, len(seeds), CHUNK)]
    t0 = time.perf_counter()
    chunks = run_sweep(run_chunk, jobs, workers=args.workers, desc=args.env, store=out.store)
    rows: dict[tuple[str, str], list[dict[str, Any]]] = {r: [] for r in runs}
    for (name, p, _, _), chunk in zip(jobs, chunks, strict=True):
        rows[name, p] += chunk
    wall = time.perf_counter() - t0
    summary = [summarise(name, p, rows[name, p], args) for name, p in runs]
    return summary, [r for key in runs for r in rows[key]], wall


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    parser = build_parser()
    args = parse_args(argv, parser)
    out = cli.open_output(parser, args, "intersection", FILES, argv)
    with out:
        summary, rows, wall = run(args, out)
        write_csvs(out.dir, "intersection", summary, rows)
        text = markdown(summary, args, wall, out.command_line.strip())
        (out.dir / "intersection.md").write_text(text)
    print(text)
    return summary


if __name__ == "__main__":
    main()
