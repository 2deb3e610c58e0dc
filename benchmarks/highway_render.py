"""Pictures through highway-env's graphics: the paper's episode as a GIF, an intersection frame.

    python -m benchmarks.highway_render                   # the paper's episode, to results/highway
    python -m benchmarks.highway_render --out docs/results/highway --estimator monte_carlo --intersection

1. The paper's episode: ``RiskCrossing-v0`` with ``renderer="highway"``, driven by an agent
   (``--agent rmpc``: :class:`agents.RMPC`, or ``smpc``) in the shared rollout loop
   (:func:`benchmarks.rollout.rollout`); before each step the agent's plan is set on the env and a
   frame drawn. Saved as ``riskcrossing_<agent>_<uncertainty>.gif`` (``--fps`` frames per second;
   ``--estimator monte_carlo`` adds the env's Monte Carlo draws to the frames).
2. ``--intersection``: one ``intersection-v1`` episode (seed ``--intersection-seed``) driven by the
   same kind of agent through :class:`risk_env.highway.IntersectionAdapter`, drawn with
   :func:`risk_env.highway.graphics.render_scene`: the route, the chosen object's truncation boxes
   and the MPC's plan. Saved as ``intersection_<agent>.gif`` and, for the step where the ego came
   closest to its chosen object, ``intersection_frame.png``.

Headless: frames are drawn on plain surfaces (no display needed).
"""

from __future__ import annotations

import argparse
import functools
import os
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

from benchmarks import cli  # noqa: E402


class FrameRecorder:
    """An agent that, before each step, shows the wrapped agent's plan in the env and records a
    frame; otherwise it is the wrapped agent (for :func:`benchmarks.rollout.rollout`)."""

    def __init__(self, agent: Any, env: Any) -> None:
        self.agent = agent
        self.env = env
        self.frames: list[np.ndarray] = []

    @property
    def last_solve(self) -> Any:
        return getattr(self.agent, "last_solve", None)

    def reset(self) -> None:
        if hasattr(self.agent, "reset"):
            self.agent.reset()
        self.frames = []

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        action, state = self.agent.predict(observation, state, episode_start, deterministic)
        report = self.last_solve
        self.env.unwrapped.set_plan(None if report is None else report.ego_trajectory[:, :2])
        self.frames.append(self.env.render())
        return action, state


def save_gif(frames: list[np.ndarray], path: Path, fps: float) -> Path:
    """An animated GIF of ``frames`` (each ``(H, W, 3)`` uint8), looping."""
    from PIL import Image

    images = [Image.fromarray(f) for f in frames]
    images[0].save(
        path, save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0, optimize=True
    )
    return path


def make_agent(kind: str, scenario: Any) -> Any:
    from agents import RMPC, SMPC

    return RMPC(scenario) if kind == "rmpc" else SMPC(scenario, risk="exact")


def paper_episode(args: argparse.Namespace) -> tuple[list[np.ndarray], Any]:
    """Frames of the paper's episode and its record."""
    import gymnasium as gym

    import risk_env  # noqa: F401  (registers RiskCrossing-v0)
    from benchmarks.rollout import rollout

    env = gym.make(
        "RiskCrossing-v0",
        render_mode="rgb_array",
        renderer="highway",
        uncertainty=args.uncertainty,
        risk_tolerance=args.tolerance,
        risk_estimator=args.estimator,
        max_steps=args.max_steps,
    )
    recorder = FrameRecorder(make_agent(args.agent, env.unwrapped.scenario), env)
    record = rollout(recorder, env, seed=args.seed)
    frames = [*recorder.frames, env.render()]  # the final state, with the last plan
    env.close()
    return frames, record


def intersection_episode(args: argparse.Namespace) -> tuple[list[np.ndarray], int, dict[str, Any]]:
    """Frames of one intersection-v1 episode, the index of the closest approach, a summary."""
    from risk_env.highway import IntersectionAdapter, RiskCostWrapper, make_intersection_env
    from risk_env.highway.adapter import ADAPTER_DEFAULTS, reached
    from risk_env.highway.graphics import render_scene
    from risk_env.prediction.belief import predict

    radii = {k: ADAPTER_DEFAULTS[k] for k in ("ego_radius", "object_radius")}
    env = RiskCostWrapper(
        make_intersection_env(), uncertainty=args.uncertainty, risk_tolerance=args.tolerance, **radii
    )
    adapter = IntersectionAdapter(
        env,
        functools.partial(make_agent, args.agent),
        uncertainty=args.uncertainty,
        risk_tolerance=args.tolerance,
    )
    obs, info = env.reset(seed=args.intersection_seed)
    frames, gaps, done, k = [], [], False, 0
    while not done:
        action, _ = adapter.predict(obs)
        obj, ego = adapter.last_object, env.unwrapped.vehicle
        report = adapter.last_solve
        frames.append(
            render_scene(
                env,
                route=adapter.route.polyline(),
                beliefs=predict(adapter.scenario, obj)[1:],
                plan=report.ego_trajectory,
                highlight=(obj[0], obj[1], adapter.scenario.object.radius),
                status=(
                    f"k = {k}  t = {k * adapter.dt:.1f} s  {args.agent.upper()} on lane {adapter.lane}",
                    f"risk = {info['risk']:.3g} (all vehicles, eps = {args.tolerance:g})",
                    f"solve {1e3 * report.solve_time:.1f} ms, {report.variant}",
                ),
            )
        )
        gaps.append(float(np.hypot(*(ego.position - obj[:2]))))
        obs, _, terminated, truncated, info = env.step(action)
        done, k = terminated or truncated, k + 1
    summary = {
        "steps": k,
        "collision": bool(env.unwrapped.vehicle.crashed),
        "goal": reached(env, adapter.destination),
    }
    env.close()
    return frames, int(np.argmin(gaps)), summary


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.highway_render``."""
    parser = cli.parser("highway_render", __doc__)
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("results/highway"),
        help="output folder for the GIFs and the PNG; the committed ones are in docs/results/highway",
    )
    parser.add_argument("--agent", choices=("rmpc", "smpc"), default="rmpc", help="who drives")
    parser.add_argument(
        "--uncertainty", choices=("low", "medium", "high"), default="low", help="Table I level"
    )
    parser.add_argument("--tolerance", type=float, default=0.0, help="epsilon [J]")
    parser.add_argument(
        "--estimator",
        choices=("exact", "monte_carlo", "worst_case", "grid"),
        default="exact",
        help="the env's risk estimator (monte_carlo also draws its samples)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the paper's episode")
    parser.add_argument("--fps", type=float, default=4.0, help="frames per second of the GIFs")
    parser.add_argument("--max-steps", type=int, default=80, help="episode step limit of the paper's episode")
    parser.add_argument("--intersection", action="store_true", help="also an intersection-v1 episode")
    parser.add_argument(
        "--intersection-seed", type=int, default=0, help="seed of the intersection-v1 episode"
    )
    return parser


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    return build_parser().parse_args(argv)


def main(argv: list[str] | None = None) -> list[Path]:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    written = []
    frames, record = paper_episode(args)
    gif = save_gif(frames, args.out / f"riskcrossing_{args.agent}_{args.uncertainty}.gif", args.fps)
    written.append(gif)
    print(
        f"{gif}: {len(frames)} frames; e_acc {record.e_acc:.1f}, d_min {record.d_min:.2f} m,"
        f" goal {record.success}, collision {record.collision}"
    )
    if args.intersection:
        from PIL import Image

        frames, closest, summary = intersection_episode(args)
        gif = save_gif(frames, args.out / f"intersection_{args.agent}.gif", args.fps)
        png = args.out / "intersection_frame.png"
        Image.fromarray(frames[closest]).save(png)
        written += [gif, png]
        print(f"{gif}: {len(frames)} frames, {summary}; {png}: step {closest} (closest approach)")
    return written


if __name__ == "__main__":
    main()
