"""Held-out two-object scenes: do the RMPC and the SMPC at epsilon = 0 keep clear of two road users
in crossings they were not tuned on?

    python -m benchmarks.heldout --scenes 4 --workers 1                 # a quick look
    python -m benchmarks.heldout --scenes 60 --workers 1 --out docs/results/heldout

The agents were developed on the paper's scene and the ``two_crossing`` preset
(:mod:`risk_env.scenario.scenes`); these scenes come from a seeded generator (:func:`make_scenes`,
reproducible from ``(seed, index)``, a prefix of a larger run is the smaller run) that draws, per
scene:

- the uncertainty level (the paper's presets in turn: low, medium, high), v_ref uniform in
  [2, 6] m/s, the object motion (``"paper"`` or ``"sampled"``, the env's own draws from the
  prediction), the ego at the paper's start at rest;
- two crossing road users, each from either side of the path (independently), heading across it
  within 0.4 rad of the perpendicular, at 1-4 m/s, timed to reach the path 2-12 s ahead at an
  arc length where the ego would be then (within 0.5-1.3 of v_ref times that time, and at least
  :data:`MIN_AHEAD` metres ahead of the ego's start), starting at least :data:`MIN_START` metres
  from the path.

The objects start far enough from the ego that the first step is feasible, so every collision
would be the agents' own. Per agent (named as in every command, :mod:`benchmarks.agent_names`;
``rmpc``: worst case; ``smpc``: exact risk, epsilon = 0 in the paper's severity unless it names
its own) the benchmark reports collisions (with a Wilson 95 % interval), goal rate, steps, fallbacks per
episode and failed solver calls, and the smallest distance to either object. Episodes run without the
MPC's wall-time cap by default (``--max-solve-time inf``: results independent of the machine's
load). Outputs in ``--out``: ``heldout.md`` and ``heldout.csv`` (one row per episode), one output
set (:mod:`benchmarks.output`; ``--resume`` goes on after an interruption).
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cli
from benchmarks.agent_names import AgentName, parse_agent
from benchmarks.sampled_rows import wilson
from benchmarks.sweep import run_sweep
from risk_env.models.path import point
from risk_env.scenario.scenario import Scenario

LEVELS: tuple[str, ...] = ("low", "medium", "high")
MOTIONS: tuple[str, ...] = ("paper", "sampled")
FILES = ("heldout.csv", "heldout.md")
"""The files a run writes in ``--out``."""


def agent(name: str) -> AgentName:
    """The agent ``name`` (an SMPC without a tolerance: epsilon = 0, the paper's severity)."""
    return parse_agent(name, ("rmpc", "smpc")).with_defaults("paper", 0.0)


MIN_AHEAD = 10.0
"""Least arc length [m] between the ego's start and where an object crosses the path."""
MIN_START = 8.0
"""Least distance [m] of an object's start from the path's crossing point."""
COLUMNS = (
    "agent",
    "index",
    "uncertainty",
    "motion",
    "v_ref",
    "collision",
    "goal",
    "steps",
    "fallbacks",
    "failed_calls",
    "d_min",
)


@dataclass(frozen=True)
class Scene:
    """One held-out scene: its uncertainty level, object motion, overrides and episode seed."""

    index: int
    uncertainty: str
    motion: str
    v_ref: float
    objects: tuple[tuple[tuple[float, float, float], float], ...]
    """Each object's (start (c1 [m], c2 [m], theta [rad]), speed [m/s])."""
    seed: int

    def scenario(self, risk_tolerance: float = 0.0, severity: str = "paper") -> Scenario:
        """The scene's scenario (epsilon ``risk_tolerance`` in the unit of ``severity``)."""
        objects = [{"start": start, "speed": speed, "turn_rate": 1e-4} for start, speed in self.objects]
        return Scenario.preset(
            self.uncertainty,
            objects=objects,
            v_ref=self.v_ref,
            risk_tolerance=risk_tolerance,
            severity=severity,
        )


def make_scenes(count: int, seed: int = 0) -> list[Scene]:
    """``count`` scenes; scene i is drawn from ``default_rng([seed, 10, i])`` (a stream of its own,
    apart from :func:`benchmarks.scenes.make_scenes`'s)."""
    if count < 0:
        raise ValueError(f"count must be >= 0, got {count}")
    return [_scene(i, np.random.default_rng([seed, 10, i])) for i in range(count)]


def _scene(index: int, rng: np.random.Generator) -> Scene:
    base = Scenario()
    path = base.path
    v_ref = float(rng.uniform(2.0, 6.0))
    motion = MOTIONS[int(rng.integers(len(MOTIONS)))]
    lam0 = path.lambda_start
    objects = []
    for _ in range(2):
        t_cross, speed = float(rng.uniform(2.0, 12.0)), float(rng.uniform(1.0, 4.0))
        lam_c = lam0 + max(MIN_AHEAD, v_ref * t_cross * float(rng.uniform(0.5, 1.3)))
        lam_c = min(lam_c, -2.0)
        cx, cy, cth = point(path, lam_c)
        side = 1.0 if rng.random() < 0.5 else -1.0
        heading = float(cth + side * (0.5 * math.pi + rng.uniform(-0.4, 0.4)))
        travel = max(MIN_START, speed * t_cross)
        start = (cx - travel * math.cos(heading), cy - travel * math.sin(heading), heading)
        objects.append((tuple(round(float(c), 4) for c in start), round(speed, 4)))
    level = LEVELS[index % len(LEVELS)]
    return Scene(index, level, motion, round(v_ref, 4), tuple(objects), seed=int(rng.integers(2**31)))


@dataclass(frozen=True)
class Job:
    agent: str
    scene: Scene
    max_solve_time: float


def run_job(job: Job) -> dict[str, Any]:
    """One episode of ``job.agent`` on ``job.scene``."""
    import gymnasium as gym

    import risk_env  # noqa: F401
    from benchmarks.rollout import build, rollout

    scene = job.scene
    name = agent(job.agent)
    scenario = scene.scenario(name.tolerance or 0.0, name.severity or "paper")
    env = gym.make("RiskCrossing-v0", scenario=scenario, object_motion=scene.motion)
    rec = rollout(build(name, env, max_solve_time=job.max_solve_time), env, seed=scene.seed)
    env.close()
    return {
        "agent": job.agent,
        "index": scene.index,
        "uncertainty": scene.uncertainty,
        "motion": scene.motion,
        "v_ref": scene.v_ref,
        "collision": rec.collision,
        "goal": rec.success,
        "steps": rec.steps,
        "fallbacks": rec.failures,
        "failed_calls": int(sum(getattr(r, "failed_calls", 0) for r in rec.reports if r is not None)),
        "d_min": round(float(np.min(rec.distance)), 3),
    }


def summarise(agent: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """One agent's episodes in numbers."""
    n = len(rows)
    collisions = sum(r["collision"] for r in rows)
    lo, hi = wilson(collisions, n)
    fallbacks = np.array([r["fallbacks"] for r in rows])
    return {
        "agent": agent,
        "episodes": n,
        "collisions": collisions,
        "ci": (lo, hi),
        "goal_rate": sum(r["goal"] for r in rows) / n,
        "fallbacks": int(fallbacks.sum()),
        "fallbacks_per_episode": float(fallbacks.mean()),
        "episodes_with_fallback": int(np.sum(fallbacks > 0)),
        "failed_calls": int(sum(r["failed_calls"] for r in rows)),
        "d_min": float(min(r["d_min"] for r in rows)),
    }


def markdown(summary: list[dict[str, Any]], command: str, wall: float, count: int, seed: int) -> str:
    lines = [
        f"`{command}`",
        "",
        f"{count} held-out two-object scenes (benchmarks.heldout, seed {seed}). Wall time"
        f" {wall:.0f} s. Collisions: count of episodes [Wilson 95 % interval]. d_min: smallest"
        " centre distance to either object over all episodes [m] (collision below r_e + r_o = 2 m).",
        "",
        "| agent | episodes | collisions | goal | fallbacks/episode (episodes with any) |"
        " failed solver calls | d_min [m] |",
        "|" + " --- |" * 7,
    ]
    for s in summary:
        lo, hi = s["ci"]
        lines.append(
            f"| {s['agent']} | {s['episodes']} | {s['collisions']} [{100 * lo:.1f}, {100 * hi:.1f} %] |"
            f" {100 * s['goal_rate']:.0f}% | {s['fallbacks_per_episode']:.2f}"
            f" ({s['episodes_with_fallback']}) | {s['failed_calls']} | {s['d_min']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.heldout``."""
    p = cli.parser("heldout", __doc__)
    p.add_argument("--scenes", type=cli.positive_int, default=30, help="held-out scenes per agent")
    p.add_argument("--seed", type=cli.nonnegative_int, default=0, help="the generator's seed")
    p.add_argument(
        "--agents",
        type=cli.agents_list(("rmpc", "smpc")),
        default="rmpc,smpc",
        help="comma list of rmpc[:RISK], smpc[:RISK][:SEVERITY:TOLERANCE][:budget=B]",
    )
    p.add_argument(
        "--max-solve-time", type=cli.time_cap, default=math.inf, help="the MPCs' wall-time cap per step [s]"
    )
    cli.add_output_options(p, Path("results/heldout"), "output directory", resume=True)
    cli.add_sweep_options(p)
    return p


def parse_args(argv: list[str] | None = None, p: argparse.ArgumentParser | None = None) -> argparse.Namespace:
    p = p or build_parser()
    args = p.parse_args(argv)
    args.agents = [str(agent(str(a))) for a in args.agents]
    return args


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    p = build_parser()
    args = parse_args(argv, p)
    out = cli.open_output(p, args, "heldout", FILES, argv)
    scenes = make_scenes(args.scenes, args.seed)
    jobs = [Job(a, s, args.max_solve_time) for a in args.agents for s in scenes]
    with out:
        t0 = time.perf_counter()
        rows = run_sweep(run_job, jobs, args.workers, args.ray, desc="held-out episodes", store=out.store)
        wall = time.perf_counter() - t0
        summary = [summarise(a, [r for r in rows if r["agent"] == a]) for a in args.agents]
        with (out.dir / "heldout.csv").open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=COLUMNS)
            writer.writeheader()
            writer.writerows(rows)
        text = markdown(summary, out.command_line.strip(), wall, args.scenes, args.seed)
        (out.dir / "heldout.md").write_text(text)
    print(text)
    return rows


if __name__ == "__main__":
    main()
