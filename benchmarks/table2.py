"""The paper's Table II: RMPC and SMPC x low/medium/high uncertainty x six risk tolerances, for
each risk method, and the shipped PPO policies on the same 36 configurations.

    python -m benchmarks.table2                      # every agent, written to results/
    python -m benchmarks.table2 --agents rmpc:worst_case,smpc:exact --uncertainty low --out results/low
    python -m benchmarks.table2 --scene two_crossing --out results/two_crossing

Writes ``table2.csv`` (one row per run), ``table2.md`` (our figures beside the paper's, the claims
checklist, timing), ``table2_runs.npz`` (every trajectory), ``table2_meta.json`` and the Fig. 3/4
PNGs, as one output set (:mod:`benchmarks.output`: a manifest, nothing mixed with an earlier run).
The terminal gets a one-screen summary (:func:`summary`): runs, collisions and failed solver steps
per agent, and the paper's claims, with a reason for each one that does not hold.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cli
from benchmarks.claims import LEVELS, check_claims
from benchmarks.output import jsonable
from benchmarks.paper_table2 import PAPER, TOLERANCES
from benchmarks.rollout import AGENTS, EpisodeRecord, available_agents, build_agent, rollout
from benchmarks.summary import summary
from benchmarks.sweep import run_sweep
from benchmarks.table2_report import CSV_COLUMNS, markdown, write_csv
from risk_env.scenario.scenario import SCENE_NAMES, SEVERITY_NAMES, Scenario

__all__ = [
    "CSV_COLUMNS",
    "LEVELS",
    "METHODS",
    "RunSpec",
    "check_claims",
    "main",
    "markdown",
    "run_one",
    "specs_for",
]
METHODS = AGENTS
FILES = (
    "table2.csv",
    "table2.md",
    "table2_runs.npz",
    "table2_meta.json",
    "fig3_trajectories.png",
    "fig4_velocities.png",
    "table2_at_a_glance.png",
)
"""The files a run writes in ``--out`` (the figures unless ``--no-figures``)."""


@dataclass(frozen=True)
class RunSpec:
    """One closed-loop run of the case study."""

    method: str
    risk_method: str
    uncertainty: str
    epsilon: float
    overrides: tuple[tuple[str, Any], ...] = ()
    seed: int = 0
    agent_options: tuple[tuple[str, Any], ...] = field(default=())
    scene: str = "paper"
    """Which road users cross (:data:`risk_env.SCENE_NAMES`)."""

    @property
    def label(self) -> str:
        return f"{self.method}/{self.risk_method}/{self.uncertainty}/eps={self.epsilon:g}"


def make_agent(spec: RunSpec, env: Any) -> Any:
    """The agent a spec names, built for the env's scenario (agents read only observations). The
    MPCs run without their wall-time cap unless ``agent_options`` sets one, so that the table does
    not depend on the machine's load (``benchmarks.timing`` and ``benchmarks.stress`` measure it)."""
    options = dict(spec.agent_options)
    if spec.method in ("RMPC", "SMPC"):
        options.setdefault("max_solve_time", math.inf)
    return build_agent(spec.method, spec.risk_method, env, spec.seed, **options)


def run_one(spec: RunSpec) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Run one spec: a CSV row and the trajectory arrays."""
    import gymnasium as gym

    import risk_env  # noqa: F401  (registers the env)

    t0 = time.perf_counter()
    env = gym.make(
        "RiskCrossing-v0",
        uncertainty=spec.uncertainty,
        risk_tolerance=spec.epsilon,
        scene=spec.scene,
        **dict(spec.overrides),
    )
    agent = make_agent(spec, env)
    record: EpisodeRecord = rollout(agent, env, seed=spec.seed)
    env.close()
    scenario = env.unwrapped.scenario
    paper = (float("nan"), float("nan"))  # the paper's figures are for its severity and scene only
    if scenario.severity == "paper" and spec.scene == "paper":
        paper = PAPER.get((spec.method, spec.uncertainty, spec.epsilon), paper)
    solve_ms = 1e3 * record.solve_time
    row = {
        "agent": f"{spec.method.lower()}:{spec.risk_method}",
        "method": spec.method,
        "risk_method": spec.risk_method,
        "uncertainty": spec.uncertainty,
        "epsilon": spec.epsilon,
        "severity": scenario.severity,
        "e_acc": round(record.e_acc, 3),
        "d_min": round(record.d_min, 3),
        "collided": record.collision,
        "reached_goal": record.success,
        "steps": record.steps,
        "failed_solves": record.failures,
        "solve_ms_median": round(float(np.median(solve_ms)), 3),
        "solve_ms_p95": round(float(np.percentile(solve_ms, 95)), 3),
        "solve_ms_max": round(float(solve_ms.max()), 3),
        "max_risk": float(f"{record.risk.max():.4g}"),  # J to 1e-6 injuries
        "wall_s": round(time.perf_counter() - t0, 3),
        "paper_e_acc": paper[0],
        "paper_d_min": paper[1],
        "fallback_soft": record.fallbacks("soft"),
        "fallback_manoeuvre": record.fallbacks("manoeuvre"),
    }
    arrays = {"ego": record.ego, "object": record.object, "actions": record.actions, "risk": record.risk}
    if record.objects.shape[1] > 1:  # several objects: each one's states and risk terms
        arrays.update(objects=record.objects, risk_terms=record.risk_terms)
    return row, arrays


def specs_for(
    methods: list[str],
    levels: list[str],
    tolerances: list[float],
    overrides: dict[str, Any],
    seed: int = 0,
    scene: str = "paper",
) -> list[RunSpec]:
    frozen = tuple(sorted(overrides.items()))
    return [
        RunSpec(*METHODS[m], level, eps, frozen, seed, scene=scene)
        for m in methods
        for level in levels
        for eps in tolerances
    ]


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.table2``."""
    p = cli.parser("table2", __doc__)
    agents = cli.agents_list(("rmpc", "smpc", "ppo"), tolerance=False, budget=False)
    p.add_argument(
        "--agents",
        type=agents,
        default=None,
        help=f"comma list of agents, from {', '.join(METHODS)} (default: all; PPO needs the rl extra)",
    )
    p.add_argument("--methods", type=agents, dest="agents", action=cli.Renamed, new="--agents")
    p.add_argument(
        "--uncertainty",
        type=cli.choices_list(LEVELS, "uncertainty"),
        default="low,medium,high",
        help="comma list of Table I levels",
    )
    p.add_argument(
        "--tolerances",
        type=cli.numbers_list(cli.nonnegative_float),
        default=",".join(f"{t:g}" for t in TOLERANCES),
        help="comma list of epsilon in the severity's unit (the default: the paper's, in J)",
    )
    p.add_argument(
        "--v-ref",
        type=cli.positive_float,
        default=None,
        help="reference speed [m/s] (default: the Scenario's, 4)",
    )
    p.add_argument(
        "--severity",
        default=None,
        choices=SEVERITY_NAMES,
        help="severity model (default: the Scenario's, paper); a severity other than paper needs"
        " --tolerances in its own unit",
    )
    cli.add_output_options(
        p,
        Path("results"),
        "output folder; the committed results are rebuilt with --out docs/results",
        resume=True,
    )
    p.add_argument(
        "--scene",
        default="paper",
        choices=SCENE_NAMES,
        help="which road users cross (risk_env.scenario.scenes)",
    )
    cli.add_sweep_options(p)
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    return p


def parse_args(argv: list[str] | None = None, p: argparse.ArgumentParser | None = None) -> argparse.Namespace:
    p = p or build_parser()
    args = p.parse_args(argv)
    if args.agents is None:
        args.agents = available_agents(args.scene)
        if not any(METHODS[m][0] == "PPO" for m in args.agents):
            print("PPO rows skipped: pip install 'riskcrossing[rl]' to score the shipped PPO policies")
    else:
        args.agents = [str(a) for a in args.agents]
    from benchmarks.rollout import SCENE_AGENTS

    if bad := [a for a in args.agents if SCENE_AGENTS.get(a, args.scene) != args.scene]:
        p.error(f"argument --agents: {', '.join(bad)} runs in --scene {SCENE_AGENTS[bad[0]]} only")
    from risk_env.risk.severity import check_tolerance

    try:
        for t in args.tolerances:
            check_tolerance(t, args.severity or "paper", "argument --tolerances: value")
    except ValueError as error:
        p.error(str(error))
    return args


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    p = build_parser()
    args = parse_args(argv, p)
    out = cli.open_output(p, args, "table2", FILES, argv)
    overrides: dict[str, Any] = {}
    if args.v_ref is not None:
        overrides["v_ref"] = args.v_ref
    if args.severity is not None:
        overrides["severity"] = args.severity
    rows: list[dict[str, Any]] = []
    arrays: dict[str, np.ndarray] = {}
    wall: dict[str, float] = {}
    with out:
        for method in args.agents:
            specs = specs_for([method], args.uncertainty, args.tolerances, overrides, scene=args.scene)
            t0 = time.perf_counter()
            results = run_sweep(run_one, specs, args.workers, args.ray, desc=method, store=out.store)
            wall[":".join(METHODS[method])] = time.perf_counter() - t0
            for spec, (row, arr) in zip(specs, results):
                rows.append(row)
                for key, value in arr.items():
                    arrays[f"{spec.label}/{key}"] = value
        claims = check_claims(rows)
        write_csv(rows, out.dir / "table2.csv")
        (out.dir / "table2.md").write_text(markdown(rows, claims, wall, args.scene))
        np.savez_compressed(out.dir / "table2_runs.npz", **arrays)
        meta = {"wall_s": wall, "args": vars(args)}
        (out.dir / "table2_meta.json").write_text(json.dumps(jsonable(meta), indent=2))
        if not args.no_figures:
            from benchmarks.figures import paper_figures

            paper_figures(rows, arrays, out.dir, Scenario.preset(scene=args.scene))
        written = [args.out / name for name in out.written()]
    print(summary(rows, claims, wall, args.out / "table2.md", [p for p in written if p.name != "table2.md"]))
    return rows


if __name__ == "__main__":
    main()
