"""Pictures through highway-env's graphics: the paper's episode as a GIF, an intersection frame.

    python -m benchmarks.highway_render                   # the paper's episode, to results/highway
    python -m benchmarks.highway_render --out docs/results/highway --estimator monte_carlo --intersection

1. The paper's episode: ``RiskCrossing-v0`` with ``renderer="highway"``, driven by an agent
   (``--agent rmpc[:RISK]``: :class:`agents.RMPC`, or ``smpc[:RISK]``; :mod:`benchmarks.agent_names`)
   in the shared rollout loop
   (:func:`benchmarks.rollout.rollout`); before each step the agent's plan is set on the env and a
   frame drawn. Saved as ``riskcrossing_<agent>_<uncertainty>.gif`` (``--fps`` frames per second;
   ``--estimator monte_carlo`` adds the env's Monte Carlo draws to the frames).
2. ``--intersection``: one ``intersection-v1`` episode (seed ``--intersection-seed``) driven by the
   same kind of agent through :class:`risk_env.highway.IntersectionAdapter`, drawn with
   :func:`risk_env.highway.graphics.render_scene`: the route, the nearest planned-for vehicle's
   truncation boxes and the MPC's plan. Saved as ``intersection_<agent>.gif`` and, for the step
   where the ego came closest to that vehicle, ``intersection_frame.png``.

Headless: frames are drawn on plain surfaces (no display needed). The files are one output set
(:mod:`benchmarks.output`).
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
from benchmarks.agent_names import parse_agent  # noqa: E402

FILES = ("riskcrossing_*.gif", "intersection_*.gif", "intersection_frame.png")
"""The files a run may write in ``--out``."""


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


def make_agent(name: str, scenario: Any, **options: Any) -> Any:
    """The MPC ``name`` (``rmpc[:RISK]`` or ``smpc[:RISK]``) for ``scenario`` (``options``: the
    MPC's, e.g. the ``object_slots`` the intersection adapter asks for)."""
    from agents import RMPC, SMPC

    agent = parse_agent(name, ("rmpc", "smpc"), tolerance=False, budget=False)
    return (RMPC if agent.kind == "rmpc" else SMPC)(scenario, risk=agent.variant, **options)


def file_tag(name: str) -> str:
    """``rmpc`` for ``rmpc:worst_case`` (a default risk is left out), ``smpc_monte_carlo`` for
    ``smpc:monte_carlo``: the agent's part of the file names."""
    from benchmarks.agent_names import RISKS

    agent = parse_agent(name, ("rmpc", "smpc"), tolerance=False, budget=False)
    return agent.kind if agent.variant == RISKS[agent.kind][0] else f"{agent.kind}_{agent.variant}"


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
        ego, report = env.unwrapped.vehicle, adapter.last_solve
        nearest = adapter.last_objects[:1]  # the nearest vehicle planned against (none: empty)
        frames.append(
            render_scene(
                env,
                route=adapter.route.polyline(),
                beliefs=[b for obj in nearest for b in predict(adapter.scenario, obj)[1:]],
                plan=report.ego_trajectory,
                highlight=None if not len(nearest) else (*nearest[0][:2], adapter.scenario.object.radius),
                status=(
                    f"k = {k}  t = {k * adapter.dt:.1f} s  {args.agent} on lane {adapter.lane}",
                    f"risk = {info['risk']:.3g} (all vehicles, eps = {args.tolerance:g})",
                    f"solve {1e3 * report.solve_time:.1f} ms, {report.variant}",
                ),
            )
        )
        gaps.append(float(np.hypot(*(ego.position - nearest[0][:2]))) if len(nearest) else np.inf)
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
    cli.add_output_options(
        parser,
        Path("results/highway"),
        "output folder for the GIFs and the PNG; the committed ones are in docs/results/highway",
    )
    parser.add_argument(
        "--agent",
        type=cli.agents_list(("rmpc", "smpc"), tolerance=False, budget=False),
        default="rmpc",
        help="who drives: rmpc[:RISK] or smpc[:RISK]",
    )
    parser.add_argument(
        "--uncertainty", choices=("low", "medium", "high"), default="low", help="Table I level"
    )
    parser.add_argument("--tolerance", type=cli.nonnegative_float, default=0.0, help="epsilon [J]")
    parser.add_argument(
        "--estimator",
        choices=("exact", "monte_carlo", "worst_case", "grid"),
        default="exact",
        help="the env's risk estimator (monte_carlo also draws its samples)",
    )
    parser.add_argument("--seed", type=cli.nonnegative_int, default=0, help="seed of the paper's episode")
    parser.add_argument("--fps", type=cli.positive_float, default=4.0, help="frames per second of the GIFs")
    parser.add_argument(
        "--max-steps", type=cli.positive_int, default=80, help="episode step limit of the paper's episode"
    )
    parser.add_argument("--intersection", action="store_true", help="also an intersection-v1 episode")
    parser.add_argument(
        "--intersection-seed", type=cli.nonnegative_int, default=0, help="seed of the intersection-v1 episode"
    )
    return parser


def parse_args(
    argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None
) -> argparse.Namespace:
    parser = parser or build_parser()
    args = parser.parse_args(argv)
    if len(args.agent) != 1:
        parser.error("argument --agent: one agent, not a list")
    args.agent = str(args.agent[0])
    from risk_env.risk.severity import check_tolerance

    try:
        check_tolerance(args.tolerance, "paper", "argument --tolerance:")
    except ValueError as error:
        parser.error(str(error))
    return args


def main(argv: list[str] | None = None) -> list[Path]:
    parser = build_parser()
    args = parse_args(argv, parser)
    out = cli.open_output(parser, args, "highway_render", FILES, argv)
    tag = file_tag(args.agent)
    with out:
        frames, record = paper_episode(args)
        gif = save_gif(frames, out.dir / f"riskcrossing_{tag}_{args.uncertainty}.gif", args.fps)
        lines = [f"{args.out / gif.name}: {len(frames)} frames; {record.summary()}"]
        if args.intersection:
            from PIL import Image

            frames, closest, summary = intersection_episode(args)
            gif = save_gif(frames, out.dir / f"intersection_{tag}.gif", args.fps)
            Image.fromarray(frames[closest]).save(out.dir / "intersection_frame.png")
            lines.append(
                f"{args.out / gif.name}: {len(frames)} frames, {summary};"
                f" {args.out / 'intersection_frame.png'}: step {closest} (closest approach)"
            )
        written = [args.out / name for name in out.written()]
    print("\n".join(lines))
    return sorted(written, key=lambda p: not p.name.startswith("riskcrossing"))


if __name__ == "__main__":
    main()
