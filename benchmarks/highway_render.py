"""Pictures through highway-env's graphics: the paper's episode as a GIF, an intersection frame.

    python -m benchmarks.highway_render                   # the paper's episode, to results/highway
    python -m benchmarks.highway_render --out docs/results/highway --estimator monte_carlo --intersection
    python -m benchmarks.highway_render --intersection --intersection-agent smpc --predictor constant

1. The paper's episode: ``RiskCrossing-v0`` with ``renderer="highway"``, driven by an agent
   (``--agent rmpc[:RISK]``: :class:`agents.RMPC`, or ``smpc[:RISK]``; :mod:`benchmarks.agent_names`)
   in the shared rollout loop
   (:func:`benchmarks.rollout.rollout`); before each step the agent's plan is set on the env and a
   frame drawn. Saved as ``riskcrossing_<agent>_<uncertainty>.gif`` (``--fps`` frames per second;
   ``--estimator monte_carlo`` adds the env's Monte Carlo draws to the frames).
2. ``--intersection``: one ``intersection-v2`` episode (seed ``--intersection-seed``, length
   ``--intersection-duration``) driven by ``--intersection-agent`` (named as in
   :mod:`benchmarks.highway_intersection`: ``rmpc``, ``smpc`` with the episode budget 0.05,
   ``smpc:probability:0.01``, ...) through :class:`risk_env.highway.IntersectionAdapter` with
   ``--predictor``, drawn with :func:`risk_env.highway.graphics.render_scene`: the route, the MPC's
   plan and every planned-for vehicle's predicted modes (each mode's truncation boxes in its own
   frame, its weight as opacity; :func:`risk_env.highway.graphics.draw_mixtures`). Saved as
   ``intersection_<agent>.gif`` (``_constant`` added for the paper's predictor) and, for the step
   where the ego came closest to the nearest planned-for vehicle, ``intersection_frame.png``.

Headless: frames are drawn on plain surfaces (no display needed). The files are one output set
(:mod:`benchmarks.output`).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

from benchmarks import cli  # noqa: E402
from benchmarks.agent_names import parse_agent  # noqa: E402
from risk_env.prediction.predictors import PREDICTOR_NAMES  # noqa: E402

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
    """Frames of one intersection-v2 episode, the index of the closest approach, a summary."""
    from benchmarks.highway_agents import make_driver, resolve
    from benchmarks.highway_episodes import make_env
    from risk_env.highway.adapter import reached
    from risk_env.highway.graphics import render_scene
    from risk_env.prediction.predictors import ConstantPredictor

    options = intersection_options(args)
    env = make_env(options, args.predictor)
    agent = resolve(args.intersection_agent, options.severity, options.budget)
    adapter = make_driver(agent, env, options, args.predictor)
    obs, info = env.reset(seed=args.intersection_seed)
    frames, gaps, done, k = [], [], False, 0
    while not done:
        action, _ = adapter.predict(obs)
        ego, report = env.unwrapped.vehicle, adapter.last_solve
        scenario = adapter.scenario
        predictor = adapter.predictor or ConstantPredictor(scenario)
        objects = adapter.last_objects  # every vehicle planned against, nearest first
        mixtures = predictor.predict_scene(objects, scenario.horizon) if len(objects) else []
        spent = "" if agent.budget is None else f", spent {adapter.spent_risk():.3g} of B = {agent.budget:g}"
        frames.append(
            render_scene(
                env,
                route=adapter.route.polyline(),
                mixtures=mixtures,
                plan=report.ego_trajectory,
                highlight=None if not len(objects) else (*objects[0][:2], scenario.object.radius),
                status=(
                    f"k = {k}  t = {k * adapter.dt:.1f} s  {agent.name} ({args.predictor}),"
                    f" lane {adapter.lane}",
                    f"risk = {info['risk']:.3g} (scored, all vehicles){spent}",
                    f"solve {1e3 * report.cpu_time:.1f} ms CPU, {report.variant}; modes: weight = opacity",
                ),
            )
        )
        gaps.append(float(np.hypot(*(ego.position - objects[0][:2]))) if len(objects) else np.inf)
        obs, _, terminated, truncated, info = env.step(action)
        done, k = terminated or truncated, k + 1
    summary = {
        "steps": k,
        "collision": bool(env.unwrapped.vehicle.crashed),
        "goal": reached(env, adapter.destination),
    }
    env.close()
    return frames, int(np.argmin(gaps)), summary


def intersection_options(args: argparse.Namespace) -> argparse.Namespace:
    """The options of :mod:`benchmarks.highway_intersection` for the episode: its defaults, with
    this command's ``--uncertainty``, ``--predictor`` and ``--intersection-duration``."""
    from benchmarks import highway_intersection

    argv = ["--uncertainty", args.uncertainty, "--predictor", args.predictor]
    options = highway_intersection.build_parser().parse_args(argv)
    options.duration = args.intersection_duration
    return options


def intersection_tag(args: argparse.Namespace) -> str:
    """The intersection GIF's name part: ``rmpc``, ``smpc_budget_0.05``, ... and ``_constant``
    for the paper's predictor."""
    name = args.intersection_agent.replace(":exact", "").replace(":worst_case", "")
    tag = name.replace(":", "_").replace("=", "_")
    return tag + ("" if args.predictor == "lane" else f"_{args.predictor}")


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
    parser.add_argument("--intersection", action="store_true", help="also an intersection-v2 episode")
    parser.add_argument(
        "--intersection-seed", type=cli.nonnegative_int, default=0, help="seed of the intersection-v2 episode"
    )
    parser.add_argument(
        "--intersection-agent",
        type=cli.agents_list(("rmpc", "smpc")),
        default="rmpc",
        help="who drives the intersection: rmpc[:RISK] or smpc[...] as in highway_intersection"
        " (smpc: the episode budget 0.05)",
    )
    parser.add_argument(
        "--predictor",
        choices=PREDICTOR_NAMES,
        default="lane",
        help="the intersection agent's predictor (its modes are drawn)",
    )
    parser.add_argument(
        "--intersection-duration",
        type=cli.positive_float,
        default=13.0,
        help="length of the intersection episode [s] (highway-env's duration)",
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
    if len(args.intersection_agent) != 1:
        parser.error("argument --intersection-agent: one agent, not a list")
    from benchmarks.highway_agents import DEFAULT_BUDGET, resolve
    from benchmarks.highway_intersection import check_duration

    try:
        args.intersection_agent = resolve(args.intersection_agent[0], "probability", DEFAULT_BUDGET).name
    except ValueError as error:
        parser.error(f"argument --intersection-agent: {error}")
    check_duration(parser, args.intersection_duration, "--intersection-duration")
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
            gif = save_gif(frames, out.dir / f"intersection_{intersection_tag(args)}.gif", args.fps)
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
