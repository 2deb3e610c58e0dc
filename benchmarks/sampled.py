r"""Risk under real uncertainty: agents over many seeded episodes with sampled object motion.

    python -m benchmarks.sampled                       # the headline table (200 episodes each)
    python -m benchmarks.sampled --episodes 20 --agents smpc:exact --tolerances 0,2500
    python -m benchmarks.sampled --severities paper,probability,injury \
        --tolerances paper=0,1000,2500 --tolerances probability=0,0.01 --tolerances injury=0,0.005
    python -m benchmarks.sampled --scene two_crossing --out results/two_crossing

With ``object_motion="sampled"`` the object's true next position and speed are drawn from the
very prediction model the agents plan with, so the env's per-step risk $R_{k+1|k}$ is the exact
expected harm of the next step. The question: does the tolerance $\epsilon$ bound what happens?

Tolerances are taken in each severity's own unit (J, probability, injuries; the ``unit`` column),
and a value that cannot be one (a probability above 1, more than 2 injuries per step) is an error.
Reported per configuration: the collision rate per episode (Wilson 95% interval), mean and 95th
percentile of the per-step risk, the share of steps whose risk exceeded $\epsilon$, the realised
harm per step (mean of $I_C s$ over the steps that happened: it should match the mean risk), the
episode's summed risk (``info["episode_risk"]``, mean and max over episodes), the realised harm
per episode (it should match the mean episode risk), e_acc, d_min and the goal rate.

``--budgets`` adds a row per episode risk budget $B$ (in the severity's own unit, checked as the
tolerances are) for each SMPC agent, built with ``risk_budget=B`` and no per-step bound
(:mod:`benchmarks.budget_rows`, written to ``budget.csv`` and a second table of ``sampled.md``).
The PPO policies read $\epsilon$ in J, so their rows are the paper severity's only. With
``--budgets`` and no ``--tolerances`` the agents that take no budget (RMPC, PPO) run at
$\epsilon = 0$ and the SMPC agents run the budget rows only.

    python -m benchmarks.sampled --agents rmpc:worst_case,smpc:exact --severities probability \
        --budgets 0.05,0.01 --episodes 200 --out docs/results/budget
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from pathlib import Path
from typing import Any

from benchmarks import cli
from benchmarks.budget_rows import BUDGET_COLUMNS, markdown_budget, summarise_budget
from benchmarks.rollout import AGENTS, available_agents
from benchmarks.sampled_rows import COLUMNS, Job, markdown, run_job, summarise, wilson
from benchmarks.sweep import run_sweep
from risk_env.scenario.scenario import SCENE_NAMES, SEVERITY_NAMES, UNCERTAINTY_PRESETS

__all__ = ["COLUMNS", "Job", "main", "markdown", "parse_tolerances", "run_job", "summarise", "wilson"]
FILES = ("sampled.csv", "sampled.md", "budget.csv")
"""The files a run writes in ``--out`` (``budget.csv`` with ``--budgets`` only)."""


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.sampled``."""
    p = cli.parser("sampled", __doc__)
    p.add_argument(
        "--agents",
        type=cli.agents_list(("rmpc", "smpc", "ppo"), tolerance=False, budget=False),
        default=None,
        help=f"comma list from {', '.join(AGENTS)} (default: all but the grid RMPC; PPO with the rl extra)",
    )
    p.add_argument(
        "--severities",
        type=cli.choices_list(SEVERITY_NAMES, "severity"),
        default="paper,plastic",
        help=f"comma list of {', '.join(SEVERITY_NAMES)}",
    )
    p.add_argument(
        "--uncertainty",
        type=cli.choices_list(UNCERTAINTY_PRESETS, "uncertainty"),
        default="medium",
        help="comma list of low, medium, high",
    )
    p.add_argument(
        "--tolerances",
        action="append",
        metavar="[SEVERITY=]EPS,...",
        help="comma list of epsilon in the severity's own unit (default: 0,1000,2500); repeat as"
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
        help="which road users cross (risk_env.scenario.scenes)",
    )
    p.add_argument(
        "--max-solve-time",
        type=cli.time_cap,
        default=math.inf,
        help="the MPC agents' wall-time cap per step [s]; inf: none, so that results do not depend on"
        " the machine's load; 0.1: the agents' own default, 20%% of T",
    )
    p.add_argument("--episodes", type=cli.positive_int, default=200, help="seeded episodes per configuration")
    p.add_argument(
        "--chunk", type=cli.positive_int, default=25, help="episodes per job (one agent build per job)"
    )
    cli.add_output_options(
        p,
        Path("results"),
        "output folder for sampled.csv and sampled.md; the committed ones are in docs/results",
        resume=True,
    )
    cli.add_sweep_options(p)
    return p


def parse_args(argv: list[str] | None = None, p: argparse.ArgumentParser | None = None) -> argparse.Namespace:
    p = p or build_parser()
    args = p.parse_args(argv)
    if args.agents is None:
        args.agents = [a for a in available_agents(args.scene) if a != "rmpc:grid"]
        if "paper" not in args.severities:  # the policies read epsilon in J
            args.agents = [a for a in args.agents if AGENTS[a][0] != "PPO"]
    else:
        args.agents = [str(a) for a in args.agents]
    from benchmarks.rollout import SCENE_AGENTS

    if bad := [a for a in args.agents if SCENE_AGENTS.get(a, args.scene) != args.scene]:
        p.error(f"argument --agents: {', '.join(bad)} runs in --scene {SCENE_AGENTS[bad[0]]} only")
    only_budgets = bool(args.budgets) and not args.tolerances
    try:
        args.tolerances = parse_tolerances(
            args.tolerances or (["0"] if only_budgets else ["0,1000,2500"]), args.severities
        )
        args.budgets = parse_tolerances(args.budgets, args.severities, "budget") if args.budgets else {}
    except ValueError as error:
        p.error(str(error))
    ppo = [a for a in args.agents if AGENTS[a][0] == "PPO"]
    if ppo and "paper" not in args.severities:
        p.error(
            f"argument --agents: {', '.join(ppo)} read epsilon in the paper severity's unit (J);"
            " run them with --severities paper"
        )
    if args.budgets and not any(AGENTS[a][0] == "SMPC" for a in args.agents):
        p.error("argument --budgets: the budget rows are the SMPC agents'; --agents names none")
    args.only_budgets = only_budgets
    return args


def parse_tolerances(
    groups: list[str], severities: list[str], what: str = "tolerance"
) -> dict[str, list[float]]:
    r"""``--tolerances`` (``what="budget"``: ``--budgets``) values -> $\epsilon$ ($B$) per severity, each
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
                f"argument {flag}: {group!r} names severity {name!r}, not one of --severities {severities}"
            )
        try:
            numbers = [float(t) for t in cli.comma_list(values)]
        except ValueError:
            raise ValueError(f"argument {flag}: {group!r}: expected numbers separated by commas") from None
        if sep:
            own[name] = numbers
        else:
            common = numbers
    out = {}
    for severity in severities:
        chosen = own.get(severity, common)
        if not chosen:
            raise ValueError(
                f"argument --{what}s: no {what}s for severity {severity!r}:"
                f" pass --{what}s {severity}=VALUE,..."
            )
        label = f"argument --{what}s: value for severity {severity!r}"
        out[severity] = [check_tolerance(e, severity, label) for e in chosen]
    return out


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    p = build_parser()
    args = parse_args(argv, p)
    out = cli.open_output(p, args, "sampled", FILES, argv)
    smpc = [a for a in args.agents if AGENTS[a][0] == "SMPC"]
    configs = [
        (a, s, u, e, None)
        for a in args.agents
        if not (args.only_budgets and a in smpc)
        for s in args.severities
        if s == "paper" or AGENTS[a][0] != "PPO"  # the policies read epsilon in J
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
    with out:
        t0 = time.perf_counter()
        results = run_sweep(run_job, jobs, args.workers, args.ray, desc="episode chunks", store=out.store)
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
        if budget_rows:
            _write_csv(out.dir / "budget.csv", BUDGET_COLUMNS, budget_rows)
        _write_csv(out.dir / "sampled.csv", COLUMNS, rows)
        text = (
            markdown(rows)
            + (f"\n{markdown_budget(budget_rows)}" if budget_rows else "")
            + f"\nWall time: {time.perf_counter() - t0:.0f} s for {len(configs)} configurations.\n"
        )
        (out.dir / "sampled.md").write_text(text)
        names = out.written()
    print(text)
    print("Wrote:\n" + "\n".join(f"  {args.out / n}" for n in names))
    return rows + budget_rows


def _write_csv(path: Path, columns: tuple[str, ...], rows: list[dict[str, Any]]) -> None:
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
