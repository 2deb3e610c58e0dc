"""The terminal summary of ``python -m benchmarks.table2``: one screen, every failure explained.

The full tables go to ``table2.md``; the terminal gets what a reader needs first: what each
column means (:data:`COLUMNS`), per agent the runs, collisions, failed solver steps and ranges of
the results, then the paper's claims, numbered and counted as listed. Each claim that does not
hold gets one line of why, computed from the runs, and the docs page that explains it
(:data:`DOCS`). Rows that look like a bug but are not (PPO rows that never change, the grid
RMPC's failed solver steps) are explained too.
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path
from typing import Any

DOCS = "docs/reproduction.md"
"""The docs page (in the repository) that explains the reproduction and its deviations."""
COLUMNS = (
    "e_acc: the accumulated path error, the sum over the run's steps of ||e_k|| (lower: nearer path)",
    "d_min: the smallest centre distance to an object over the run [m] (a collision below r_e + r_o)",
    "failed solver steps: steps where the MPC's solver found no plan and a fallback level acted",
)
"""One line per column of the agent table that needs a definition."""
ANCHORS = {
    "grid": "#the-grid-rmpcs-failed-solves",
    "monotone": "#d_min-and-epsilon",
    "collisions": "#smpc-collisions-at-epsilon-0",
    "ppo": "#ppo-rows",
    "claims": "#why-some-claims-do-not-hold",
}
"""Sections of :data:`DOCS` that the summary points to (tests check that they exist)."""
FALLBACK_DOCS = "docs/agents.md#fallback"
"""Where the MPC's fallback is described."""
WIDTH = 96
"""Longest line printed [characters]."""

_SEVERITY_WHY = {
    "paper": "the paper's severity is zero at matched kinetic energies, so the SMPC slows to the"
    " object's speed and drives into it",
    "plastic": "a plastic impact at relative speed u costs 0.5 m_e m_o/(m_e+m_o) u^2, so epsilon"
    " admits slow bumps, and the SMPC uses them",
    "probability": "epsilon bounds each step's collision probability, which the SMPC spends",
}


def _label(method: str, variant: str) -> str:
    """The agent's name (:mod:`benchmarks.agent_names`)."""
    return f"{method.lower()}:{variant}"


def _range(values: list[float]) -> str:
    lo, hi = min(values), max(values)
    return f"{lo:.1f}" if abs(hi - lo) < 0.05 else f"{lo:.1f}-{hi:.1f}"


def _wrap(text: str, indent: str) -> list[str]:
    return textwrap.wrap(text, WIDTH, initial_indent=indent, subsequent_indent=indent, break_on_hyphens=False)


def agent_table(rows: list[dict[str, Any]]) -> list[str]:
    """One line per agent: runs, collisions, failed solver steps, e_acc and d_min ranges, solve p95."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["method"], r["risk_method"]), []).append(r)
    lines = [
        f"{'agent':<18}{'runs':>5}{'collided':>9}{'failed solver steps':>21}"
        f"{'e_acc':>13}{'d_min [m]':>11}{'solve p95 [ms]':>16}"
    ]
    for (method, variant), sel in groups.items():
        lines.append(
            f"{_label(method, variant):<18}{len(sel):>5}{sum(bool(r['collided']) for r in sel):>9}"
            f"{sum(int(r['failed_solves']) for r in sel):>21}{_range([r['e_acc'] for r in sel]):>13}"
            f"{_range([r['d_min'] for r in sel]):>11}{max(r['solve_ms_p95'] for r in sel):>16.1f}"
        )
    return lines


def grouped(claims: list[tuple[str, bool | None, str]]) -> list[tuple[str, bool | None, list[str]]]:
    """Claims that differ only in their first ``(variant)`` and share a verdict, as one line:
    ``(text, verdict, the original claims)``."""
    out: list[tuple[str, bool | None, list[str]]] = []
    templates: list[str] = []
    variants: list[list[str]] = []
    for claim, ok, _ in claims:
        match = re.search(r"\(([a-z_]+)\)", claim)
        template = claim if match is None else claim[: match.start()] + "({})" + claim[match.end() :]
        for i, (_, verdict, members) in enumerate(out):
            if match is not None and templates[i] == template and verdict == ok:
                members.append(claim)
                variants[i].append(match.group(1))
                break
        else:
            out.append((template, ok, [claim]))
            templates.append(template)
            variants.append([match.group(1)] if match else [])
    return [
        (text.format(", ".join(names)) if names else text, ok, members)
        for (text, ok, members), names in zip(out, variants)
    ]


def _unit(rows: list[dict[str, Any]]) -> str:
    return "" if rows and rows[0]["severity"] == "probability" else " J"


def why(claims: list[str], rows: list[dict[str, Any]]) -> str:
    """One sentence of why ``claims`` (variants of one claim) do not hold, from the runs, with the
    docs section that explains it."""
    index = {(r["method"], r["risk_method"], r["uncertainty"], r["epsilon"]): r for r in rows}
    pattern = r"SMPC \(([a-z_]+)\) at or below RMPC \(([a-z_]+)\)"
    below = [m.groups() for c in claims if (m := re.match(pattern, c))]
    if below:
        rmpc = below[0][1]
        cases: dict[tuple[str, float], list[str]] = {}
        for smpc, _ in below:
            for (method, variant, level, eps), s in index.items():
                r = index.get(("RMPC", rmpc, level, eps))
                if (method, variant) == ("SMPC", smpc) and r is not None:
                    if not (s["e_acc"] <= r["e_acc"] and s["d_min"] <= r["d_min"]):
                        cases.setdefault((level, eps), []).append(
                            f"smpc:{smpc} e_acc {s['e_acc']:.1f}, d_min {s['d_min']:.1f} m"
                        )
        parts = []
        for (level, eps), found in list(cases.items())[:2]:
            r = index[("RMPC", rmpc, level, eps)]
            parts.append(
                f"{level} uncertainty, epsilon {eps:g}{_unit(rows)}: {'; '.join(found)};"
                f" rmpc:{rmpc} e_acc {r['e_acc']:.1f}, d_min {r['d_min']:.1f} m"
            )
        failed = sum(
            int(r["failed_solves"]) for r in rows if (r["method"], r["risk_method"]) == ("RMPC", rmpc)
        )
        stall = f" (its solver stalls: {failed} failed solver steps)" if rmpc == "grid" and failed else ""
        return (
            f"{' | '.join(parts)}. At epsilon = 0 the SMPC keeps clear of the whole"
            f" truncation box, like the exact worst case; the {rmpc} RMPC keeps less{stall}."
            f" {DOCS}{ANCHORS['claims']}"
        )
    if claims == ["No run collides"]:
        collided = [r for r in rows if r["collided"]]
        methods = "/".join(sorted({r["method"] for r in collided}))
        within = [r for r in collided if r["max_risk"] <= r["epsilon"] + 1e-6]
        severity = collided[0]["severity"] if collided else "paper"
        first = min(within, key=lambda r: r["epsilon"], default=None)
        unit = _unit(rows)
        example = (
            f" (e.g. {first['max_risk']:.1f}{unit} at {first['epsilon']:g}{unit})"
            if first is not None
            else ""
        )
        eps = ", epsilon > 0" if all(r["epsilon"] > 0 for r in collided) else ""
        share = "each within its" if len(within) == len(collided) else f"{len(within)} of them within their"
        return (
            f"{len(collided)} of {len(rows)} runs collided (all {methods}{eps}), {share}"
            f" tolerance{example}: {_SEVERITY_WHY.get(severity, '')}. {DOCS}{ANCHORS['collisions']}"
        )
    falls = [
        m.group(1) for c in claims if (m := re.match(r"SMPC \(([a-z_]+)\) d_min falls as epsilon grows", c))
    ]
    if falls:
        rises = []
        for variant in falls:
            for level in ("low", "medium", "high"):
                runs = sorted(
                    (
                        r
                        for r in rows
                        if (r["method"], r["risk_method"], r["uncertainty"]) == ("SMPC", variant, level)
                    ),
                    key=lambda r: r["epsilon"],
                )
                up = [b for a, b in zip(runs, runs[1:]) if b["d_min"] > a["d_min"] + 0.05]
                if up:
                    eps = ", ".join(f"{r['epsilon']:g}" for r in up)
                    rises.append(f"{variant} at {level} rises at epsilon = {eps}{_unit(rows)}")
        return (
            f"{'; '.join(rises)}: each run is a local optimum of a non-convex problem, and runs that"
            f" collide or fall back end early, so d_min need not fall step by step."
            f" {DOCS}{ANCHORS['monotone']}"
        )
    return f"see {DOCS}{ANCHORS['claims']}"


def notes(rows: list[dict[str, Any]]) -> list[str]:
    """Explanations of what looks wrong but is not: failed solves, rows that never change."""
    out: list[str] = []
    constant: list[tuple[str, int]] = []
    for method, variant in dict.fromkeys((r["method"], r["risk_method"]) for r in rows):
        sel = [r for r in rows if (r["method"], r["risk_method"]) == (method, variant)]
        failed = sum(int(r["failed_solves"]) for r in sel)
        if failed:
            levels = [
                lv
                for lv in ("low", "medium", "high")
                if any(r["failed_solves"] for r in sel if r["uncertainty"] == lv)
            ]
            if (method, variant) == ("RMPC", "grid"):
                reason = "the grid's constraint is a staircase"
                where = f"{DOCS}{ANCHORS['grid']}"
            else:
                reason = "a warm start did not converge"
                where = FALLBACK_DOCS
            out += _wrap(
                f"{_label(method, variant)}: {failed} failed solver steps ({', '.join(levels)}), soft problem"
                f" or manoeuvre ({reason}). {where}",
                "  ",
            )
        if method == "PPO" and len(sel) > 1:
            if all((r["e_acc"], r["d_min"]) == (sel[0]["e_acc"], sel[0]["d_min"]) for r in sel):
                constant.append((variant, len(sel)))
    if constant:
        names = " and ".join(v for v, _ in constant)
        out += _wrap(
            f"ppo:{names}: each the same in all {constant[0][1]} configurations: the policy sees neither"
            f" the uncertainty level nor epsilon, and the object moves alike in all. {DOCS}{ANCHORS['ppo']}",
            "  ",
        )
    return out


def summary(
    rows: list[dict[str, Any]],
    claims: list[tuple[str, bool | None, str]],
    wall: dict[str, float],
    report: Path,
    written: list[Path],
) -> str:
    """The terminal report of a Table II run (at most 36 lines); ``report`` is the full markdown,
    ``written`` the other files."""
    agents = len({(r["method"], r["risk_method"]) for r in rows})
    levels = len({r["uncertainty"] for r in rows})
    tolerances = len({r["epsilon"] for r in rows})
    lines = [
        f"Table II: {len(rows)} closed loops ({agents} agents x {levels} uncertainty levels x"
        f" {tolerances} tolerances) in {sum(wall.values()):.0f} s.",
        *agent_table(rows),
        *COLUMNS,
    ]
    listed = grouped(claims)
    counts = [sum(ok is verdict for _, ok, _ in listed) for verdict in (True, False, None)]
    lines.append(
        f"The paper's claims, {len(listed)} as listed: {counts[0]} hold, {counts[1]} do not"
        + (f", {counts[2]} not run." if counts[2] else ".")
    )
    for i, (text, ok, members) in enumerate(listed, 1):
        verdict = {True: "holds", False: "NO", None: "not run"}[ok]
        lines += _wrap(f"{i}. {verdict:<6} {text}", "  ")
        if ok is False:
            lines += _wrap("why: " + why(members, rows), "    ")
    extra = notes(rows)
    if extra:
        lines += ["Also:", *extra]
    files = ", ".join(p.name for p in written)
    lines += _wrap(
        f"Written to {report.parent}/: {report.name} (beside the paper's), {files}",
        "",
    )
    return "\n".join(lines)
