"""The rows of :mod:`benchmarks.sampled`: seeded episodes with sampled object motion, run
(:func:`run_job`) and summarised per configuration (:func:`summarise`, :func:`markdown`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.rollout import AGENTS, build_agent, rollout

COLUMNS = (
    "agent",
    "scene",
    "severity",
    "unit",
    "uncertainty",
    "epsilon",
    "episodes",
    "collision_rate",
    "collision_ci_low",
    "collision_ci_high",
    "risk_mean",
    "risk_p95",
    "violation_rate",
    "harm_per_step",
    "episode_risk_mean",
    "episode_risk_max",
    "harm_per_episode",
    "e_acc_mean",
    "d_min_mean",
    "d_min_min",
    "goal_rate",
    "failed_solves",
    "solve_ms_median",
    "fallback_soft",
    "fallback_manoeuvre",
    "fallbacks_per_episode",
    "episodes_with_fallback",
)


@dataclass(frozen=True)
class Job:
    agent: str
    severity: str
    uncertainty: str
    epsilon: float
    seeds: tuple[int, ...]
    scene: str = "paper"
    """Which road users cross (:data:`risk_env.SCENE_NAMES`)."""
    budget: float | None = None
    """An episode risk budget B: the agent gets ``risk_budget=B`` and no per-step bound."""
    max_solve_time: float | None = None
    """The MPC's wall-time cap per step [s] (None: its default, 20 % of T; ``math.inf``: none)."""


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion."""
    if n == 0:
        return (float("nan"), float("nan"))
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def run_job(job: Job) -> list[dict[str, Any]]:
    """Episodes of one configuration (the agent is built once and reset per episode)."""
    import gymnasium as gym

    import risk_env  # noqa: F401
    from risk_env.models.ops import NUMPY
    from risk_env.risk.severity import make_severity

    env = gym.make(
        "RiskCrossing-v0",
        uncertainty=job.uncertainty,
        risk_tolerance=job.epsilon,
        severity=job.severity,
        object_motion="sampled",
        scene=job.scene,
    )
    options: dict[str, Any] = {}
    if job.budget is not None:
        options.update(risk_budget=job.budget, risk_tolerance=math.inf)
    if job.max_solve_time is not None and not job.agent.startswith("ppo"):
        options["max_solve_time"] = job.max_solve_time
    agent = build_agent(*AGENTS[job.agent], env, **options)
    scenario = env.unwrapped.scenario
    severities = [make_severity(scenario.for_object(i)) for i in range(len(scenario.objects))]
    radii = scenario.collision_distances
    out = []
    for seed in job.seeds:
        rec = rollout(agent, env, seed=seed)
        # realised harm of each step: sum_i I_C,i s_i at the state reached (only the last step can
        # collide), each object with its own mass and radius
        harm = np.zeros(rec.steps)
        if rec.collision:
            e = rec.ego[-1]
            for o, r, severity, there in zip(rec.objects[-1], radii, severities, rec.info["present"]):
                if there and np.hypot(e[0] - o[0], e[1] - o[1]) <= r:
                    harm[-1] += float(severity.value(e[3], e[2], o[3], o[2], NUMPY))
        out.append(
            {
                "collision": rec.collision,
                "success": rec.success,
                "risk": rec.risk,
                "harm": harm,
                "episode_risk": float(rec.info["episode_risk"]),
                "violations": int(np.sum(rec.risk > job.epsilon * (1 + 1e-6) + 1e-9)),
                "e_acc": rec.e_acc,
                "d_min": rec.d_min,
                "failures": rec.failures,
                "soft": rec.fallbacks("soft"),
                "manoeuvre": rec.fallbacks("manoeuvre"),
                "solve_ms": 1e3 * rec.solve_time,
            }
        )
    env.close()
    return out


def _sig(x: float, digits: int = 4) -> float:
    """``x`` rounded to ``digits`` significant digits (risks span J to 1e-6 injuries)."""
    return float(f"{x:.{digits}g}")


def summarise(job: Job, episodes: list[dict[str, Any]]) -> dict[str, Any]:
    from risk_env.risk.severity import make_severity
    from risk_env.scenario.scenario import Scenario

    n = len(episodes)
    collisions = sum(e["collision"] for e in episodes)
    lo, hi = wilson(collisions, n)
    risk = np.concatenate([e["risk"] for e in episodes])
    harm = np.concatenate([e["harm"] for e in episodes])
    episode_risk = np.array([e["episode_risk"] for e in episodes])
    solve = np.concatenate([e["solve_ms"] for e in episodes])
    return {
        "agent": job.agent,
        "scene": job.scene,
        "severity": job.severity,
        "unit": make_severity(Scenario(severity=job.severity)).unit,
        "uncertainty": job.uncertainty,
        "epsilon": job.epsilon,
        "episodes": n,
        "collision_rate": round(collisions / n, 4),
        "collision_ci_low": round(lo, 4),
        "collision_ci_high": round(hi, 4),
        "risk_mean": _sig(risk.mean()),
        "risk_p95": _sig(np.percentile(risk, 95)),
        "violation_rate": round(sum(e["violations"] for e in episodes) / len(risk), 4),
        "harm_per_step": _sig(harm.mean()),
        "episode_risk_mean": _sig(episode_risk.mean()),
        "episode_risk_max": _sig(episode_risk.max()),
        "harm_per_episode": _sig(harm.sum() / n),
        "e_acc_mean": round(float(np.mean([e["e_acc"] for e in episodes])), 2),
        "d_min_mean": round(float(np.mean([e["d_min"] for e in episodes])), 2),
        "d_min_min": round(float(np.min([e["d_min"] for e in episodes])), 2),
        "goal_rate": round(sum(e["success"] for e in episodes) / n, 4),
        "failed_solves": int(sum(e["failures"] for e in episodes)),
        "solve_ms_median": round(float(np.median(solve)), 2),
        "fallback_soft": int(sum(e["soft"] for e in episodes)),
        "fallback_manoeuvre": int(sum(e["manoeuvre"] for e in episodes)),
        "fallbacks_per_episode": round(sum(e["failures"] for e in episodes) / n, 3),
        "episodes_with_fallback": int(sum(e["failures"] > 0 for e in episodes)),
    }


def markdown(rows: list[dict[str, Any]]) -> str:
    scenes = sorted({r.get("scene", "paper") for r in rows})
    lines = [
        "# Sampled object motion: does epsilon bound what happens?",
        "",
        *([f"Scene {', '.join(scenes)} (risk_env.scenario.scenes).", ""] if scenes != ["paper"] else []),
        "Risks, eps and harm in the severity's own unit (given with eps). Harm/step = mean realised",
        "I_C s per step; with calibrated risk it matches Risk mean (both are per-step expected harm).",
        "Episode risk = info['episode_risk'], the summed risk of an episode (mean and max over",
        "episodes); harm/episode is its realised counterpart. Collisions: share of episodes.",
        "",
        "| agent | severity | unc. | eps | episodes | collisions/episode [95% CI] | risk mean | risk p95 |"
        " steps > eps | harm/step | episode risk mean (max) | harm/episode | e_acc | d_min mean (min) |"
        " goal | fallbacks (soft / manoeuvre) | fallbacks/episode (episodes with any) |",
        "|" + " --- |" * 17,
    ]
    for r in rows:
        lines.append(
            f"| {r['agent']} | {r['severity']} | {r['uncertainty']} | {r['epsilon']:g} {r['unit']} | "
            f"{r['episodes']} | {100 * r['collision_rate']:.1f}% "
            f"[{100 * r['collision_ci_low']:.1f}, {100 * r['collision_ci_high']:.1f}] | "
            f"{r['risk_mean']:.3g} | {r['risk_p95']:.3g} | {100 * r['violation_rate']:.1f}% | "
            f"{r['harm_per_step']:.3g} | {r['episode_risk_mean']:.3g} ({r['episode_risk_max']:.3g}) | "
            f"{r['harm_per_episode']:.3g} | {r['e_acc_mean']:.1f} | "
            f"{r['d_min_mean']:.1f} ({r['d_min_min']:.1f}) | "
            f"{100 * r['goal_rate']:.0f}% | "
            f"{r['failed_solves']} ({r['fallback_soft']} / {r['fallback_manoeuvre']}) | "
            f"{r['fallbacks_per_episode']:.2f} ({r['episodes_with_fallback']}) |"
        )
    return "\n".join(lines) + "\n"
