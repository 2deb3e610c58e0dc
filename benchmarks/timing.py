"""How fast and how reliable are the MPC agents? The paper's closed loop, solve by solve.

    python -m benchmarks.timing --out docs/results/timing.txt
    python -m benchmarks.timing --agents smpc:exact --jit --out docs/results/timing_jit.txt

Each agent drives ``RiskCrossing-v0`` (ego and the deterministic object of the paper) for every
uncertainty level and risk tolerance, up to ``--steps`` steps (an episode also ends at a collision
or the goal). A step's time is the whole ``agent.predict`` call as :class:`agents.SolveReport`
measures it (initial guess, solver, fallback, the plan's risk re-evaluation), capped by the
agents' ``max_solve_time`` (``--max-solve-time``; default 20 % of T). Printed per agent: solve time
per step median / p95 / p99 / max [ms], fallback steps by level (soft / manoeuvre), steps the cap
cut short, solver iterations (median), the real-time margin against the sample time T
(``T / p95``, and the share of T left by the slowest step), the time to build the solvers, and per
configuration e_acc, d_min and the steps taken. Targets on the project's 2-core machine (median /
p95): RMPC and exact SMPC 5 / 15 ms, Monte Carlo SMPC (J = 500) 40 / 80 ms, no fallback.

``--jit`` runs the solvers on compiled code (generated C, ``$CC`` at ``-O1``; see
:mod:`agents.mpc.nlp.solver`): about 40 s for the exact SMPC's three solvers, shared by every
uncertainty level
and tolerance, paid once per machine (the libraries are kept in ``$RISKMPC_JIT_CACHE``, default
``~/.cache/riskcrossing/jit``); the "build" time printed is what this run spent building and
compiling. The Monte Carlo SMPC's code (500 draws per step) would take many minutes to compile and
meets its target without. Timings on a shared machine are noisy: run it alone. Agents are named as
in every command (:mod:`benchmarks.agent_names`); ``--out FILE`` writes the report and its
manifest ``FILE-STEM.manifest.json`` beside it (:mod:`benchmarks.output`).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import risk_env  # noqa: F401  (registers RiskCrossing-v0)
from agents import RMPC, SMPC, PathFollowingMPC
from benchmarks import cli
from benchmarks.rollout import rollout
from risk_env import RISK_TOLERANCES, UNCERTAINTY_PRESETS, Scenario

AGENTS: dict[str, tuple[str, Callable[..., PathFollowingMPC]]] = {
    "rmpc:worst_case": ("RMPC, worst case (box)", lambda sc, **kw: RMPC(sc, **kw)),
    "rmpc:grid": ("RMPC, L-point grid", lambda sc, **kw: RMPC(sc, risk="grid", **kw)),
    "smpc:exact": ("SMPC, exact risk", lambda sc, **kw: SMPC(sc, **kw)),
    "smpc:monte_carlo": (
        "SMPC, Monte Carlo",
        lambda sc, samples=None, **kw: SMPC(sc, risk="monte_carlo", samples=samples, **kw),
    ),
}
"""Every agent timed (:mod:`benchmarks.agent_names`) -> (description, its constructor)."""
TARGETS_MS = {"rmpc:worst_case": (5.0, 15.0), "smpc:exact": (5.0, 15.0), "smpc:monte_carlo": (40.0, 80.0)}
"""(median, p95) solve-time targets per step [ms]."""


@dataclass
class Episode:
    """One closed loop: per-step solve data and the episode's metrics."""

    uncertainty: str
    epsilon: float
    times: list[float] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    failures: int = 0
    soft: int = 0
    manoeuvre: int = 0
    capped: int = 0
    free_steps: int = 0
    e_acc: float = 0.0
    d_min: float = float("inf")
    collision: bool = False
    steps: int = 0


def run_episode(agent: PathFollowingMPC, env: gym.Env) -> Episode:
    """Drive ``env`` with ``agent`` for one episode (the shared rollout loop) and keep the solve data."""
    record = rollout(agent, env, seed=0)
    return Episode(
        uncertainty="",
        epsilon=record.epsilon,
        times=list(record.solve_time),
        iterations=[r.iterations for r in record.reports],
        failures=record.failures,
        soft=record.fallbacks("soft"),
        manoeuvre=record.fallbacks("manoeuvre"),
        capped=sum(bool(getattr(r, "capped", False)) for r in record.reports),
        free_steps=sum(r.variant == "free" for r in record.reports),
        e_acc=record.e_acc,
        d_min=record.d_min,
        collision=record.collision,
        steps=record.steps,
    )


def summarise(name: str, episodes: list[Episode], build_time: float, dt: float) -> list[str]:
    """The agent's lines of the report."""
    t = 1e3 * np.concatenate([e.times for e in episodes])
    its = np.concatenate([e.iterations for e in episodes])
    med, p95, p99, worst = np.median(t), np.percentile(t, 95), np.percentile(t, 99), t.max()
    failures = sum(e.failures for e in episodes)
    soft, manoeuvre = sum(e.soft for e in episodes), sum(e.manoeuvre for e in episodes)
    target = TARGETS_MS.get(name)
    verdict = ""
    if target is not None:
        ok = med <= target[0] and p95 <= target[1] and failures == 0
        verdict = f"  target {target[0]:g} / {target[1]:g} ms, no fallback: {'met' if ok else 'NOT met'}"
    lines = [
        f"{AGENTS[name][0]} [{name}]: {len(episodes)} episodes, {len(t)} solves, build {build_time:.2f} s",
        f"  solve time per step [ms]: median {med:.2f}  p95 {p95:.2f}  p99 {p99:.2f}  max {worst:.2f}"
        f"{verdict}",
        f"  fallback steps {failures} (soft {soft}, manoeuvre {manoeuvre})"
        f"  capped {sum(e.capped for e in episodes)}"
        f"  iterations median {np.median(its):g} (max {its.max()})"
        f"  steps without a reachable box ('free') {sum(e.free_steps for e in episodes)}",
        f"  real time vs T = {1e3 * dt:g} ms: T/p95 = {1e3 * dt / p95:.0f}x,"
        f" slowest step leaves {100 * (1 - worst / (1e3 * dt)):.1f}% of T",
        "  uncertainty  eps [J]  steps  e_acc  d_min  collision  fallbacks  median [ms]",
    ]
    for e in episodes:
        lines.append(
            f"  {e.uncertainty:>11}  {e.epsilon:7g}  {e.steps:5d}  {e.e_acc:5.1f}  {e.d_min:5.2f}"
            f"  {'yes' if e.collision else 'no':>9}  {e.failures:8d}  {1e3 * np.median(e.times):11.2f}"
        )
    return lines


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.timing``."""
    parser = cli.parser("timing", __doc__)
    parser.add_argument("--steps", type=cli.positive_int, default=40, help="step limit per episode")
    parser.add_argument(
        "--agents",
        type=cli.agents_list(("rmpc", "smpc"), tolerance=False, budget=False),
        default="rmpc:worst_case,smpc:exact,smpc:monte_carlo,rmpc:grid",
        help=f"comma list, from {', '.join(AGENTS)}",
    )
    parser.add_argument(
        "--uncertainty",
        type=cli.choices_list(UNCERTAINTY_PRESETS, "uncertainty"),
        default="low,medium,high",
        help="comma list of Table I levels",
    )
    parser.add_argument(
        "--tolerances",
        type=cli.numbers_list(cli.nonnegative_float),
        default=",".join(f"{e:g}" for e in RISK_TOLERANCES),
        help="comma list of risk tolerances epsilon [J]",
    )
    parser.add_argument("--solver", default="fatrop", choices=("fatrop", "ipopt"), help="NLP solver")
    parser.add_argument(
        "--samples",
        type=cli.positive_int,
        default=None,
        help="Monte Carlo draws J (default: the Scenario's, 500)",
    )
    parser.add_argument(
        "--jit", action="store_true", help="run the solvers on compiled C (the first build compiles ~40 s)"
    )
    parser.add_argument(
        "--max-iter",
        type=cli.positive_int,
        default=None,
        help="solver iteration limit per call (default: the agent's)",
    )
    parser.add_argument(
        "--cold-starts",
        type=cli.nonnegative_int,
        default=None,
        help="cold starts after a failed warm one (default: the agent's)",
    )
    parser.add_argument(
        "--max-solve-time",
        type=cli.time_cap,
        default=None,
        help="wall-time cap of a step [s] (default: the agents' own, 20%% of T; inf: none)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="also write the report to this file (default: print only; the committed reports are"
        " docs/results/timing.txt and timing_jit.txt)",
    )
    parser.add_argument(
        "--overwrite", action="store_true", help="replace a report of another configuration at --out"
    )
    return parser


def main(argv: list[str] | None = None) -> None:
    parser = build_parser()
    args = parser.parse_args(argv)
    names = [str(a) for a in args.agents]
    levels, tolerances = args.uncertainty, args.tolerances
    out = None
    if args.out is not None:
        if args.out.is_dir():
            parser.error(
                f"--out {args.out}: a folder; give the report's file name, e.g. {args.out / 'timing.txt'}"
            )
        out = cli.open_output(parser, args, args.out.stem, [args.out.name], argv, out=args.out.parent)

    options = {"solver": args.solver, "jit": args.jit}
    if args.max_iter is not None:
        options["max_iter"] = args.max_iter
    if args.cold_starts is not None:
        options["cold_starts"] = args.cold_starts
    if args.max_solve_time is not None:
        options["max_solve_time"] = args.max_solve_time
    total = len(names) * len(levels) * len(tolerances) * args.steps
    report: list[str] = []
    with tqdm(total=total, desc="closed loops", unit="step") as progress:
        for name in names:
            make = AGENTS[name][1]
            kwargs = dict(options, samples=args.samples) if name == "smpc:monte_carlo" else dict(options)
            episodes, build_time = [], 0.0
            for level in levels:
                for epsilon in tolerances:
                    progress.set_postfix_str(f"{name} {level} eps={epsilon:g}")
                    env = gym.make(
                        "RiskCrossing-v0", uncertainty=level, risk_tolerance=epsilon, max_steps=args.steps
                    )
                    t0 = time.perf_counter()
                    agent = make(env.unwrapped.scenario, **kwargs)
                    build_time += time.perf_counter() - t0
                    episode = run_episode(agent, env)
                    episode.uncertainty = level
                    episodes.append(episode)
                    progress.update(args.steps)  # an early end still counts its budget
            report += summarise(name, episodes, build_time, Scenario().dt) + [""]
    text = "\n".join(report).rstrip()
    print(text)
    if out is not None:
        with out:
            (out.dir / args.out.name).write_text(text + "\n")


if __name__ == "__main__":
    main()
