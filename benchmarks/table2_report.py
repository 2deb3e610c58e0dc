"""What ``python -m benchmarks.table2`` writes: ``table2.csv`` (:func:`write_csv`) and
``table2.md`` (:func:`markdown`: our figures beside the paper's, the claims, the timing)."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.claims import LEVELS, Claim
from risk_env.scenario.scenario import Scenario

CSV_COLUMNS = (
    "agent",
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
"""``agent``: the agent's name (:mod:`benchmarks.agent_names`); ``method`` and ``risk_method``:
its class and variant; ``failed_solves``: steps where the solver found no plan and a fallback
level acted (``fallback_soft`` + ``fallback_manoeuvre``)."""
ORDER = {"RMPC": 0, "SMPC": 1, "PPO": 2}
"""The paper's two agents, then the learned baseline."""


def agent_name(row: dict[str, Any]) -> str:
    """The agent of a row in the grammar of :mod:`benchmarks.agent_names`."""
    return row.get("agent") or f"{row['method'].lower()}:{row['risk_method']}"


def markdown(
    rows: list[dict[str, Any]], claims: list[Claim], wall: dict[str, float], scene: str = "paper"
) -> str:
    lines = ["# Table II: ours beside the paper's", ""]
    if scene != "paper":
        lines += [
            f"Scene `{scene}` (risk_env.scenario.scenes): the paper's figures are for its one-object scene.",
            "",
        ]
    lines.append(
        "Each cell: ours (paper). e_acc: the accumulated path error, sum over the steps of ||e_k||;"
        " d_min: the smallest centre distance to an object [m]. `*` marks a collision."
    )
    units = sorted({_unit(r.get("severity", "paper")) for r in rows})
    lines.append(f"eps in the severity's unit: {', '.join(units)}.")
    groups = sorted({(r["method"], r["risk_method"]) for r in rows}, key=lambda g: (ORDER[g[0]], g[1]))
    levels = [lv for lv in LEVELS if any(r["uncertainty"] == lv for r in rows)]
    for method, risk in groups:
        kind = "training" if method == "PPO" else "risk"
        section = f"{method.lower()}-{risk}"  # a pymdownx.snippets section, for the docs
        lines += [
            "",
            f"## {method.lower()}:{risk} ({method}, {kind}: {risk})",
            "",
            f"<!-- --8<-- [start:{section}] -->",
        ]
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
    holding = sum(ok is True for _, ok, _ in claims)
    lines += ["", "## The paper's claims", "", "<!-- --8<-- [start:claims] -->"]
    lines.append(f"{holding} of the {len(claims)} claims below hold on these runs.")
    lines.append("")
    for i, (claim, ok, evidence) in enumerate(claims, 1):
        verdict = "holds" if ok else ("not run" if ok is None else "**does not hold**")
        lines.append(f"{i}. {claim}: {verdict} ({evidence})")
    lines += ["<!-- --8<-- [end:claims] -->", "", "## Timing", "", "<!-- --8<-- [start:timing] -->"]
    lines.append(
        "| agent | runs | wall [s] | solve median [ms] | solve p95 [ms] | solve max [ms] |"
        " failed solver steps (soft / manoeuvre) |"
    )
    lines.append("| --- | --- | --- | --- | --- | --- | --- |")
    for method, risk in groups:
        sel = [r for r in rows if (r["method"], r["risk_method"]) == (method, risk)]
        lines.append(
            f"| {agent_name(sel[0])} | {len(sel)} | {wall.get(f'{method}:{risk}', float('nan')):.1f} | "
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
