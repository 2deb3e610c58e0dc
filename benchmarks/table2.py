"""The paper's Table II: RMPC and SMPC x low/medium/high uncertainty x six risk tolerances, for
each risk method, and the shipped PPO policies on the same 36 configurations.

    python -m benchmarks.table2                      # every agent, written to results/
    python -m benchmarks.table2 --methods rmpc:worst_case,smpc:exact --uncertainty low
    python -m benchmarks.table2 --scene two_crossing --out results/two_crossing

Writes ``table2.csv`` (one row per run), ``table2.md`` (our figures beside the paper's, the claims
checklist, timing), ``table2_runs.npz`` (every trajectory), ``table2_meta.json`` and the Fig. 3/4
PNGs. The terminal gets a one-screen summary (:func:`summary`): runs, collisions and failed solves
per agent, and the paper's claims, with a reason for each one that does not hold.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cli
from benchmarks.paper_table2 import PAPER, TOLERANCES
from benchmarks.rollout import AGENTS, EpisodeRecord, available_agents, build_agent, rollout
from benchmarks.summary import summary
from benchmarks.sweep import run_sweep
from risk_env.scenario.scenario import SCENE_NAMES, SEVERITY_NAMES, Scenario

METHODS = AGENTS
LEVELS = ("low", "medium", "high")
CSV_COLUMNS = (
    "method",
    "risk_method",
    "uncertainty",
    "epsilon",
    "severity",
    "e_acc",
    "d_min",
    "collided",
    "reached_goal",
    "steps",
    "failed_solves",
    "solve_ms_median",
    "solve_ms_p95",
    "solve_ms_max",
    "max_risk",
    "wall_s",
    "paper_e_acc",
    "paper_d_min",
    "fallback_soft",
    "fallback_manoeuvre",
)


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


# --- the paper's claims -------------------------------------------------------------------------


def check_claims(rows: list[dict[str, Any]]) -> list[tuple[str, bool | None, str]]:
    """Each claim of the paper's Sec. VIII as (claim, holds, evidence); None when not run."""
    index = {(r["method"], r["risk_method"], r["uncertainty"], r["epsilon"]): r for r in rows}
    claims: list[tuple[str, bool | None, str]] = []
    rmpc_methods = sorted({r["risk_method"] for r in rows if r["method"] == "RMPC"})
    smpc_methods = sorted({r["risk_method"] for r in rows if r["method"] == "SMPC"})
    levels = [lv for lv in LEVELS if any(r["uncertainty"] == lv for r in rows)]
    for rm in rmpc_methods:
        spreads = []
        for lv in levels:
            runs = [r for r in rows if (r["method"], r["risk_method"], r["uncertainty"]) == ("RMPC", rm, lv)]
            if len(runs) > 1:
                e = [r["e_acc"] for r in runs]
                d = [r["d_min"] for r in runs]
                spreads.append((lv, max(e) - min(e), max(d) - min(d), float(np.mean(e))))
        if spreads:
            # within 1 % of e_acc and 5 cm of d_min: the solver's tolerance, not a behaviour change
            ok = all(de <= 0.01 * mean_e and dd <= 0.05 for _, de, dd, mean_e in spreads)
            text = ", ".join(
                f"{lv}: e_acc spread {de:.2f}, d_min spread {dd:.2f} m" for lv, de, dd, _ in spreads
            )
            claims.append((f"RMPC ({rm}) does not depend on epsilon", ok, text))
        means = [
            np.mean(
                [
                    r["d_min"]
                    for r in rows
                    if (r["method"], r["risk_method"], r["uncertainty"]) == ("RMPC", rm, lv)
                ]
            )
            for lv in levels
        ]
        if len(means) > 1:
            ok = bool(np.all(np.diff(means) > 0))
            claims.append(
                (
                    f"RMPC ({rm}) d_min grows with uncertainty",
                    ok,
                    ", ".join(f"{lv} {m:.2f} m" for lv, m in zip(levels, means)),
                )
            )
    for rm in rmpc_methods:
        for sm in smpc_methods:
            pairs = [
                (index[("RMPC", rm, lv, eps)], index[("SMPC", sm, lv, eps)])
                for (meth, risk, lv, eps) in index
                if meth == "RMPC" and risk == rm and ("SMPC", sm, lv, eps) in index
            ]
            if pairs:
                e_ok = sum(s["e_acc"] <= r["e_acc"] for r, s in pairs)
                d_ok = sum(s["d_min"] <= r["d_min"] for r, s in pairs)
                claims.append(
                    (
                        f"SMPC ({sm}) below RMPC ({rm}) in e_acc and d_min",
                        e_ok == len(pairs) and d_ok == len(pairs),
                        f"e_acc lower in {e_ok}/{len(pairs)} runs, d_min lower in {d_ok}/{len(pairs)}",
                    )
                )
    for sm in smpc_methods:
        parts, ok = [], True
        for lv in levels:
            runs = sorted(
                (r for r in rows if (r["method"], r["risk_method"], r["uncertainty"]) == ("SMPC", sm, lv)),
                key=lambda r: r["epsilon"],
            )
            if len(runs) > 1:
                d = [r["d_min"] for r in runs]
                falls = bool(np.all(np.diff(d) <= 0.05)) and d[-1] < d[0] - 0.05
                ok &= falls
                parts.append(f"{lv}: " + " > ".join(f"{x:.2f}" for x in d))
        if parts:
            claims.append((f"SMPC ({sm}) d_min falls as epsilon grows", ok, "; ".join(parts)))
    collided = [
        f"{r['method']}/{r['risk_method']}/{r['uncertainty']}/{r['epsilon']:g}" for r in rows if r["collided"]
    ]
    claims.append(("No run collides", not collided, ", ".join(collided) or f"0 of {len(rows)} runs"))
    return claims


# --- reports ------------------------------------------------------------------------------------


def markdown(
    rows: list[dict[str, Any]],
    claims: list[tuple[str, bool | None, str]],
    wall: dict[str, float],
    scene: str = "paper",
) -> str:
    lines = ["# Table II: ours beside the paper's", ""]
    if scene != "paper":
        lines += [
            f"Scene `{scene}` (risk_env.scenario.scenes): the paper's figures are for its one-object scene.",
            "",
        ]
    lines.append("Each cell: ours (paper). e_acc = sum of ||e_k||; d_min [m]. `*` marks a collision.")
    units = sorted({_unit(r.get("severity", "paper")) for r in rows})
    lines.append(f"eps in the severity's unit: {', '.join(units)}.")
    order = {"RMPC": 0, "SMPC": 1, "PPO": 2}  # the paper's two, then the learned baseline
    groups = sorted({(r["method"], r["risk_method"]) for r in rows}, key=lambda g: (order[g[0]], g[1]))
    levels = [lv for lv in LEVELS if any(r["uncertainty"] == lv for r in rows)]
    for method, risk in groups:
        kind = "training" if method == "PPO" else "risk"
        section = f"{method.lower()}-{risk}"  # a pymdownx.snippets section, for the docs
        lines += ["", f"## {method}, {kind}: {risk}", "", f"<!-- --8<-- [start:{section}] -->"]
        header = "| eps | " + " | ".join(f"{lv} e_acc | {lv} d_min" for lv in levels) + " |"
        lines += [header, "|" + " --- |" * (1 + 2 * len(levels))]
        for eps in sorted({r["epsilon"] for r in rows}):
            cells = []
            for lv in levels:
                match = [
                    r
                    for r in rows
                    if (r["method"], r["risk_method"], r["uncertainty"], r["epsilon"])
                    == (method, risk, lv, eps)
                ]
                if not match:
                    cells += ["", ""]
                    continue
                r = match[0]
                star = "*" if r["collided"] else ""
                cells.append(f"{r['e_acc']:.1f}{star} ({_fmt(r['paper_e_acc'])})")
                cells.append(f"{r['d_min']:.1f}{star} ({_fmt(r['paper_d_min'])})")
            lines.append(f"| {eps:g} | " + " | ".join(cells) + " |")
        lines.append(f"<!-- --8<-- [end:{section}] -->")
    lines += ["", "## The paper's claims", "", "<!-- --8<-- [start:claims] -->"]
    for claim, ok, evidence in claims:
        verdict = "holds" if ok else ("not run" if ok is None else "**does not hold**")
        lines.append(f"- {claim}: {verdict} ({evidence})")
    lines += ["<!-- --8<-- [end:claims] -->", "", "## Timing", "", "<!-- --8<-- [start:timing] -->"]
    lines.append(
        "| method | risk | runs | wall [s] | solve median [ms] | solve p95 [ms] | solve max [ms] |"
        " fallbacks (soft / manoeuvre) |"
    )
    lines.append("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for method, risk in groups:
        sel = [r for r in rows if (r["method"], r["risk_method"]) == (method, risk)]
        lines.append(
            f"| {method} | {risk} | {len(sel)} | {wall.get(f'{method}:{risk}', float('nan')):.1f} | "
            f"{np.median([r['solve_ms_median'] for r in sel]):.1f} | "
            f"{max(r['solve_ms_p95'] for r in sel):.1f} | "
            f"{max(r['solve_ms_max'] for r in sel):.1f} | {sum(r['failed_solves'] for r in sel)}"
            f" ({sum(r['fallback_soft'] for r in sel)} / {sum(r['fallback_manoeuvre'] for r in sel)}) |"
        )
    lines.append("<!-- --8<-- [end:timing] -->")
    return "\n".join(lines) + "\n"


def _unit(severity: str) -> str:
    """The unit of the severity named ``severity`` (J, probability, injuries)."""
    from risk_env.risk.severity import make_severity

    return make_severity(Scenario(severity=severity)).unit


def _fmt(x: float) -> str:
    return "-" if x != x else f"{x:.1f}"


def write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.table2``."""
    p = cli.parser("table2", __doc__)
    p.add_argument(
        "--methods",
        default=None,
        help=f"comma list of agents, from {', '.join(METHODS)} (default: all; PPO needs the rl extra)",
    )
    p.add_argument("--uncertainty", default="low,medium,high", help="comma list of Table I levels")
    p.add_argument(
        "--tolerances",
        default=",".join(f"{t:g}" for t in TOLERANCES),
        help="comma list of epsilon in the severity's unit (default: the paper's, in J)",
    )
    p.add_argument(
        "--v-ref", type=float, default=None, help="reference speed [m/s] (default: the Scenario's, 4)"
    )
    p.add_argument(
        "--severity",
        default=None,
        choices=SEVERITY_NAMES,
        help="severity model (default: the Scenario's, paper); a severity other than paper needs"
        " --tolerances in its own unit",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=Path("results"),
        help="output folder; the committed results are rebuilt with --out docs/results",
    )
    p.add_argument(
        "--scene",
        default="paper",
        choices=SCENE_NAMES,
        help="which road users cross (risk_env.scenario.scenes; default: the paper's one object)",
    )
    cli.add_sweep_options(p)
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    return p


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = build_parser()
    args = p.parse_args(argv)
    if args.methods is None:
        args.methods = available_agents(args.scene)
        if not any(METHODS[m][0] == "PPO" for m in args.methods):
            print("PPO rows skipped: pip install 'riskcrossing[rl]' to score the shipped PPO policies")
    else:
        args.methods = cli.comma_list(args.methods)
    unknown = [m for m in args.methods if m not in METHODS]
    if unknown:
        p.error(f"unknown method(s) {unknown}; expected from {list(METHODS)}")
    args.uncertainty = cli.comma_list(args.uncertainty)
    bad = [u for u in args.uncertainty if u not in LEVELS]
    if bad:
        p.error(f"unknown uncertainty {bad}; expected from {list(LEVELS)}")
    try:
        args.tolerances = [float(t) for t in cli.comma_list(args.tolerances)]
    except ValueError:
        p.error(f"--tolerances must be numbers, got {args.tolerances!r}")
    if any(t < 0 for t in args.tolerances):
        p.error("--tolerances must be >= 0")
    from risk_env.risk.severity import check_tolerance

    try:
        for t in args.tolerances:
            check_tolerance(t, args.severity or "paper", "--tolerances value")
    except ValueError as error:
        p.error(str(error))
    return args


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    args = parse_args(argv)
    overrides: dict[str, Any] = {}
    if args.v_ref is not None:
        overrides["v_ref"] = args.v_ref
    if args.severity is not None:
        overrides["severity"] = args.severity
    args.out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    arrays: dict[str, np.ndarray] = {}
    wall: dict[str, float] = {}
    for method in args.methods:
        specs = specs_for([method], args.uncertainty, args.tolerances, overrides, scene=args.scene)
        t0 = time.perf_counter()
        results = run_sweep(run_one, specs, args.workers, args.ray, desc=method)
        wall[":".join(METHODS[method])] = time.perf_counter() - t0
        for spec, (row, arr) in zip(specs, results):
            rows.append(row)
            for key, value in arr.items():
                arrays[f"{spec.label}/{key}"] = value
        write_csv(rows, args.out / "table2.csv")  # keep what is done if a later method fails
    claims = check_claims(rows)
    (args.out / "table2.md").write_text(markdown(rows, claims, wall, args.scene))
    np.savez_compressed(args.out / "table2_runs.npz", **arrays)
    (args.out / "table2_meta.json").write_text(
        json.dumps({"wall_s": wall, "args": _jsonable(vars(args))}, indent=2)
    )
    written = [args.out / "table2.csv", args.out / "table2_runs.npz", args.out / "table2_meta.json"]
    if not args.no_figures:
        from benchmarks.figures import paper_figures

        written += paper_figures(rows, arrays, args.out, Scenario.preset(scene=args.scene))
    print(summary(rows, claims, wall, args.out / "table2.md", written))
    return rows


def _jsonable(d: dict[str, Any]) -> dict[str, Any]:
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in d.items()}


if __name__ == "__main__":
    main()
