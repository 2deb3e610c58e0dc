"""The paper's claims (Sec. VIII), checked on Table II runs (:func:`check_claims`).

A comparison says "lower" only where one value is strictly lower, and names ties as ties (the
exact SMPC at epsilon = 0 is the RMPC: P = 0 is the box, so the two runs are the same).
"""

from __future__ import annotations

from typing import Any

import numpy as np

LEVELS = ("low", "medium", "high")
Claim = tuple[str, "bool | None", str]
"""(claim, holds (None: not run), evidence)."""


def _compare(pairs: list[tuple[dict[str, Any], dict[str, Any]]], column: str) -> tuple[int, int, int]:
    """(lower, tied, higher): runs where the SMPC's ``column`` is below, equal to, above the RMPC's."""
    lower = sum(s[column] < r[column] for r, s in pairs)
    tied = sum(s[column] == r[column] for r, s in pairs)
    return lower, tied, len(pairs) - lower - tied


def _counts(column: str, lower: int, tied: int, higher: int) -> str:
    n = lower + tied + higher
    parts = [f"{column} lower in {lower} of {n} runs"]
    if tied:
        parts.append(f"tied in {tied}")
    if higher:
        parts.append(f"higher in {higher}")
    return ", ".join(parts)


def chain(values: list[float]) -> str:
    """``values`` (2 decimals) joined by ``>``, ``=`` or ``<`` as each pair compares when shown."""
    shown = [f"{x:.2f}" for x in values]
    out = shown[:1]
    for a, b in zip(shown, shown[1:]):
        sign = "=" if a == b else (">" if float(a) > float(b) else "<")
        out += [sign, b]
    return " ".join(out)


def check_claims(rows: list[dict[str, Any]]) -> list[Claim]:
    """Each claim of the paper's Sec. VIII as (claim, holds, evidence); None when not run."""
    index = {(r["method"], r["risk_method"], r["uncertainty"], r["epsilon"]): r for r in rows}
    claims: list[Claim] = []
    rmpc_methods = sorted({r["risk_method"] for r in rows if r["method"] == "RMPC"})
    smpc_methods = sorted({r["risk_method"] for r in rows if r["method"] == "SMPC"})
    levels = [lv for lv in LEVELS if any(r["uncertainty"] == lv for r in rows)]

    def runs(method: str, risk: str, level: str) -> list[dict[str, Any]]:
        return [r for r in rows if (r["method"], r["risk_method"], r["uncertainty"]) == (method, risk, level)]

    for rm in rmpc_methods:
        spreads = []
        for lv in levels:
            sel = runs("RMPC", rm, lv)
            if len(sel) > 1:
                e = [r["e_acc"] for r in sel]
                d = [r["d_min"] for r in sel]
                spreads.append((lv, max(e) - min(e), max(d) - min(d), float(np.mean(e))))
        if spreads:
            # within 1 % of e_acc and 5 cm of d_min: the solver's tolerance, not a behaviour change
            ok = all(de <= 0.01 * mean_e and dd <= 0.05 for _, de, dd, mean_e in spreads)
            text = ", ".join(
                f"{lv}: e_acc spread {de:.2f}, d_min spread {dd:.2f} m" for lv, de, dd, _ in spreads
            )
            claims.append((f"RMPC ({rm}) does not depend on epsilon", ok, text))
        means = [np.mean([r["d_min"] for r in runs("RMPC", rm, lv)]) for lv in levels]
        if len(means) > 1:
            ok = bool(np.all(np.diff(means) > 0))
            text = ", ".join(f"{lv} {m:.2f} m" for lv, m in zip(levels, means))
            claims.append((f"RMPC ({rm}) d_min grows with uncertainty", ok, text))
    for rm in rmpc_methods:
        for sm in smpc_methods:
            pairs = [
                (index[("RMPC", rm, lv, eps)], index[("SMPC", sm, lv, eps)])
                for (meth, risk, lv, eps) in index
                if meth == "RMPC" and risk == rm and ("SMPC", sm, lv, eps) in index
            ]
            if pairs:
                e = _compare(pairs, "e_acc")
                d = _compare(pairs, "d_min")
                claims.append(
                    (
                        f"SMPC ({sm}) at or below RMPC ({rm}) in e_acc and d_min",
                        e[2] == 0 and d[2] == 0,
                        f"{_counts('e_acc', *e)}; {_counts('d_min', *d)}",
                    )
                )
    for sm in smpc_methods:
        parts, ok = [], True
        for lv in levels:
            sel = sorted(runs("SMPC", sm, lv), key=lambda r: r["epsilon"])
            if len(sel) > 1:
                d = [r["d_min"] for r in sel]
                falls = bool(np.all(np.diff(d) <= 0.05)) and d[-1] < d[0] - 0.05
                ok &= falls
                parts.append(f"{lv}: {chain(d)}")
        if parts:
            claims.append((f"SMPC ({sm}) d_min falls as epsilon grows", ok, "; ".join(parts)))
    where = [
        f"{r['method'].lower()}:{r['risk_method']} ({r['uncertainty']}, {r['epsilon']:g})"
        for r in rows
        if r["collided"]
    ]
    claims.append(("No run collides", not where, ", ".join(where) or f"0 of {len(rows)} runs"))
    return claims
