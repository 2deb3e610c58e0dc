"""The episode-risk-budget rows of :mod:`benchmarks.sampled`: one row per (agent, severity,
uncertainty, budget B), the agent an SMPC with ``risk_budget=B`` and no per-step bound
(``risk_tolerance=math.inf``; :mod:`agents.mpc.nlp.risk_budget`).

Each row sets the episode's summed risk (``info["episode_risk"]``, mean and max over the episodes)
against B, with the realised collision rate per episode (Wilson 95 % interval; with the
probability severity B bounds it), the realised harm per episode (with the injury severity B
bounds its mean), e_acc, the goal rate, the fallback steps (soft / manoeuvre) and the episodes with
any fallback, and the check: episodes without a fallback whose episode risk exceeds B by more than
1e-6 relative (:data:`RELATIVE_SLACK`). It must be 0.
"""

from __future__ import annotations

from typing import Any

import numpy as np

RELATIVE_SLACK = 1e-6
"""An episode risk above ``B * (1 + RELATIVE_SLACK)`` exceeds the budget."""
BUDGET_COLUMNS = (
    "agent",
    "scene",
    "severity",
    "unit",
    "uncertainty",
    "budget",
    "episodes",
    "episode_risk_mean",
    "episode_risk_max",
    "collision_rate",
    "collision_ci_low",
    "collision_ci_high",
    "harm_per_episode",
    "e_acc_mean",
    "goal_rate",
    "fallback_soft",
    "fallback_manoeuvre",
    "episodes_with_fallback",
    "over_budget_without_fallback",
)


def over_budget(episode_risk: float, budget: float) -> bool:
    """Whether an episode's summed risk exceeds ``budget`` (by more than :data:`RELATIVE_SLACK`
    relative)."""
    return episode_risk > budget * (1.0 + RELATIVE_SLACK)


def summarise_budget(row: dict[str, Any], budget: float, episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """The budget row from ``row`` (:func:`benchmarks.sampled.summarise` of the same episodes) and
    the episodes' records (with ``episode_risk`` and ``failures``)."""
    fell_back = [e["failures"] > 0 for e in episodes]
    over = sum(
        over_budget(e["episode_risk"], budget) for e, fb in zip(episodes, fell_back, strict=True) if not fb
    )
    out = {k: row[k] for k in BUDGET_COLUMNS if k in row}
    out.update(
        budget=budget,
        episodes_with_fallback=int(np.sum(fell_back)),
        over_budget_without_fallback=int(over),
    )
    return out


def markdown_budget(rows: list[dict[str, Any]]) -> str:
    """The budget rows as a Markdown table."""
    lines = [
        "## Episode risk budget B (SMPC, `risk_budget=B`, no per-step bound)",
        "",
        "Episode risk = info['episode_risk'] (mean and max over episodes), in the severity's unit, set",
        "against B. Collisions: share of episodes [Wilson 95% CI]; with the probability severity B bounds",
        "it. Check: episodes without any fallback whose episode risk exceeds B (1e-6 relative); must be 0.",
        "",
        "| agent | severity | unc. | B | episodes | episode risk mean (max) | collisions/episode [95% CI] |"
        " harm/episode | e_acc | goal | fallback steps (soft / manoeuvre) | episodes with fallback |"
        " over B without fallback |",
        "|" + " --- |" * 13,
    ]
    for r in rows:
        lines.append(
            f"| {r['agent']} | {r['severity']} | {r['uncertainty']} | {r['budget']:g} {r['unit']} | "
            f"{r['episodes']} | {r['episode_risk_mean']:.3g} ({r['episode_risk_max']:.3g}) | "
            f"{100 * r['collision_rate']:.2f}% "
            f"[{100 * r['collision_ci_low']:.2f}, {100 * r['collision_ci_high']:.2f}] | "
            f"{r['harm_per_episode']:.3g} | {r['e_acc_mean']:.1f} | {100 * r['goal_rate']:.0f}% | "
            f"{r['fallback_soft']} / {r['fallback_manoeuvre']} | {r['episodes_with_fallback']} | "
            f"{r['over_budget_without_fallback']} |"
        )
    return "\n".join(lines) + "\n"
