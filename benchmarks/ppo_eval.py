r"""Score a trained PPO policy fast on the batched env, and summarise several seeds.

:func:`evaluate` runs seeded episodes of the paper's scenario with sampled object motion (as
``benchmarks.sampled`` does, but 64 at a time in the batched env): episode $i$ has seed
``seed + i``. :func:`seed_table` gives mean $\pm$ std over training seeds as Markdown.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

METRICS = ("e_acc", "collision_rate", "goal_rate", "episode_cost", "d_min")
"""What :func:`evaluate` reports, each a mean over episodes (rates in [0, 1])."""


def evaluate(
    path: Path,
    episodes: int = 512,
    uncertainty: str = "medium",
    epsilon: float = 0.0,
    seed: int = 0,
    batch: int = 64,
) -> dict[str, float]:
    r"""Mean e_acc ($\sum_k \|e_k\|$, $k = 0, \dots,$ steps), collision and goal rates, the PPO cost per
    episode
    (:class:`agents.ppo.training.RewardWeights` with the policy's saved weights) and d_min [m] of
    ``episodes`` deterministic episodes of the policy at ``path`` (in the scene it was trained on)."""
    import json

    import gymnasium as gym

    import risk_env
    from agents.ppo.policy import PPOAgent

    train = json.loads(Path(path).with_suffix(".json").read_text()).get("args", {})
    scale, collision_cost = float(train.get("cost_scale", 1000.0)), float(train.get("collision_cost", 1.0))
    rows: dict[str, list[float]] = {k: [] for k in METRICS}
    for start in range(0, episodes, batch):
        n = min(batch, episodes - start)
        env = gym.make_vec(
            risk_env.ENV_ID,
            num_envs=n,
            vectorization_mode="vector_entry_point",
            uncertainty=uncertainty,
            risk_tolerance=epsilon,
            severity=train.get("severity", "paper"),
            object_motion="sampled",
            scene=train.get("scene", "paper"),
        )
        scenario = env.unwrapped.base_scenario
        agent = PPOAgent.load(path, scenario=scenario)
        obs, info = env.reset(seed=[seed + start + i for i in range(n)])
        e_acc = np.linalg.norm(info["path_error"], axis=1)
        d_min = np.asarray(info["distance"], dtype=float).copy()
        cost, running = np.zeros(n), np.ones(n, dtype=bool)
        collided, reached = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        while running.any():
            action, _ = agent.predict(obs)
            obs, _, terminated, truncated, info = env.step(action)
            r = running
            e_acc[r] += np.linalg.norm(info["path_error"][r], axis=1)
            d_min[r] = np.minimum(d_min[r], info["distance"][r])
            excess = np.maximum(info["risk"][r] - epsilon, 0.0) / scale
            cost[r] += excess + collision_cost * info["collision"][r]
            collided[r] |= info["collision"][r]
            reached[r] |= info["is_success"][r]
            running = r & ~(terminated | truncated)
        env.close()
        rows["e_acc"] += e_acc.tolist()
        rows["collision_rate"] += collided.astype(float).tolist()
        rows["goal_rate"] += reached.astype(float).tolist()
        rows["episode_cost"] += cost.tolist()
        rows["d_min"] += d_min.tolist()
    return {k: float(np.mean(v)) for k, v in rows.items()}


def seed_table(results: dict[int, dict[str, float]], best: int, header: str) -> str:
    r"""Markdown: one row per seed and the mean $\pm$ std (sample std, ddof 1) over seeds."""
    lines = [header, "", "| seed | " + " | ".join(METRICS) + " |", "| --- |" + " --- |" * len(METRICS)]
    for s, r in results.items():
        mark = " (shipped)" if s == best else ""
        lines.append(f"| {s}{mark} | " + " | ".join(_fmt(k, r[k]) for k in METRICS) + " |")
    stats = []
    for k in METRICS:
        values = np.array([r[k] for r in results.values()])
        std = float(values.std(ddof=1)) if len(values) > 1 else 0.0
        stats.append(f"{_fmt(k, float(values.mean()))} ± {_fmt(k, std)}")
    lines.append(f"| mean ± std over {len(results)} | " + " | ".join(stats) + " |")
    return "\n".join(lines) + "\n"


def _fmt(key: str, value: float) -> str:
    if key.endswith("_rate"):
        return f"{100 * value:.1f}%"
    return f"{value:.3g}" if key == "episode_cost" else f"{value:.1f}"


def best_seed(results: dict[int, dict[str, float]], cost_limit: float) -> int:
    """The seed to ship: among the seeds whose mean episode cost is within ``cost_limit`` (all, if
    none is), the fewest collisions, then the highest goal rate, then the lowest e_acc."""

    def key(s: int) -> tuple[Any, ...]:
        r = results[s]
        return (r["collision_rate"], -r["goal_rate"], r["e_acc"])

    within = [s for s, r in results.items() if r["episode_cost"] <= cost_limit]
    return min(within or list(results), key=key)
