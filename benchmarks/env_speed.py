"""How fast is ``RiskCrossing-v0``? Its step beside Gymnasium's CartPole-v1 and Pendulum-v1, timed
in the same run, and the risk estimators alone.

    python -m benchmarks.env_speed --repeat 10 --out docs/results
    python -m benchmarks.env_speed --repeat 10 --near-only --out docs/results

It prints two tables (and writes them to ``OUT/env_speed.txt``, ``env_speed_near.txt`` with
``--near-only``):

- the references: us/step of ``gym.make("CartPole-v1")`` and ``gym.make("Pendulum-v1")`` under
  seeded random actions, resetting at each episode's end;
- per risk estimator: steps/s and us/step of ``gym.make("RiskCrossing-v0", ...)`` (the same default
  wrappers) under a constant action (v_ref straight ahead, which passes close to the object),
  resetting at each episode's end, and that step as a multiple of each reference's; then one risk
  evaluation for a single ego state (us) and for a batch of B ego states (ms), numpy, against the
  object's one-step belief (Monte Carlo with the scenario's J = ``mc_samples``). ``exact, sampled``
  is the exact estimator with ``object_motion="sampled"``; ``(no risk)`` replaces the estimator by
  a stub, so it shows what the env costs around the risk; ``exact, 4 objects`` (and ``(no risk),
  4 objects``) steps the ``"four_crossing"`` scene (:mod:`risk_env.scenario.scenes`), four objects with
  four risk terms per step.

Each repetition times every env in turn, so that a busy machine slows them alike; shown is the best
of R repetitions (time.perf_counter). The ratios travel between machines; the absolute times do not.
``--out`` writes the tables with their manifest (:mod:`benchmarks.output`).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks import cli
from risk_env import ENV_ID, ESTIMATOR_NAMES, Scenario, make_estimator, predict
from risk_env.risk.estimators import signed_box_distance

REFERENCES = ("CartPole-v1", "Pendulum-v1")
"""Gymnasium's classic-control envs our step is measured against."""
TARGETS = {"exact": 3.0, "(no risk)": 2.0}
"""Issue 15's targets: at most this many Pendulum-v1 steps per RiskCrossing-v0 step."""


def best_time(fn: Callable[[], object], number: int, repeat: int) -> float:
    """Best mean wall time [s] of ``fn`` over ``repeat`` runs of ``number`` calls."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


class _NoRisk:
    """A stub estimator: the env's cost around the risk."""

    name = "none"

    def risk(self, ego: np.ndarray, belief: object, rng: object = None) -> float:
        return 0.0

    def risk_one(self, ego: tuple[float, ...], belief: object, rng: object = None) -> float:
        return 0.0


def stepper(env_id: str, steps: int, **kwargs: Any) -> Callable[[], None]:
    """A function that runs ``steps`` steps of ``gym.make(env_id, **kwargs)`` (default wrappers),
    resetting at each episode's end: seeded random actions for the references, for ours the
    constant action (v_ref, 0). ``estimator="none"`` puts in the no-risk stub."""
    no_risk = kwargs.pop("estimator", None) == "none"
    env = gym.make(env_id, **kwargs)
    if no_risk:
        env.unwrapped.estimators = (_NoRisk(),) * len(env.unwrapped.estimators)
    if env_id == ENV_ID:
        actions = [np.array([env.unwrapped.scenario.ego.v_ref, 0.0], dtype=np.float32)] * steps
    else:
        env.action_space.seed(0)
        actions = [env.action_space.sample() for _ in range(steps)]
    env.reset(seed=0)

    def run() -> None:
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()

    run()  # warm up
    return run


def step_times(envs: dict[str, Callable[[], None]], steps: int, repeat: int) -> dict[str, float]:
    """Seconds per step of each env: the best of ``repeat`` rounds, each timing every env in turn."""
    best = dict.fromkeys(envs, float("inf"))
    for _ in range(repeat):
        for name, run in envs.items():
            t0 = time.perf_counter()
            run()
            best[name] = min(best[name], (time.perf_counter() - t0) / steps)
    return best


def risk_times(
    name: str, scenario: Scenario, batch: int, repeat: int, near_only: bool = False
) -> tuple[float, float]:
    """Seconds for one risk evaluation (single ego state) and for a batch of ``batch`` states
    (uniform within 6 m of the object's mean; ``near_only``: only states whose disc meets the box)."""
    estimator = make_estimator(name, scenario)
    start = scenario.object.start
    belief = predict(scenario, (start.x, start.y, start.theta, scenario.object.speed, 0.0), steps=1)[1]
    rng = np.random.default_rng(0)
    single = np.array([float(belief.x) - 3.2, float(belief.y), 0.0, 4.0])
    draw = 8 * batch if near_only else batch
    states = np.column_stack(
        [
            float(belief.x) + rng.uniform(-6.0, 6.0, draw),
            float(belief.y) + rng.uniform(-6.0, 6.0, draw),
            rng.uniform(-np.pi, np.pi, draw),
            rng.uniform(-4.0, 8.0, draw),
        ]
    )
    if near_only:
        gap = signed_box_distance(
            states[:, 0] - belief.x, states[:, 1] - belief.y, belief.half_x, belief.half_y
        )
        states = states[gap < scenario.collision_distance][:batch]
    t_single = best_time(lambda: estimator.risk(single, belief, rng=rng), 200, repeat)
    number = 3 if name == "monte_carlo" else 20
    t_batch = best_time(lambda: estimator.risk(states, belief, rng=rng), number, repeat)
    return t_single, t_batch


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.env_speed``."""
    parser = cli.parser("env_speed", __doc__)
    parser.add_argument("--steps", type=cli.positive_int, default=2000, help="env steps per repetition")
    parser.add_argument("--repeat", type=cli.positive_int, default=5, help="repetitions; the best is shown")
    parser.add_argument("--batch", type=cli.positive_int, default=1000, help="ego states in the batch")
    parser.add_argument(
        "--near-only", action="store_true", help="batch only ego states whose disc meets the truncation box"
    )
    cli.add_output_options(
        parser,
        None,
        "also write the tables to OUT/env_speed.txt (OUT/env_speed_near.txt with --near-only)"
        " (default: print only; the committed ones are in docs/results)",
    )
    return parser


def main(argv: list[str] | None = None) -> str:
    parser = build_parser()
    args = parser.parse_args(argv)
    name = "env_speed_near" if args.near_only else "env_speed"
    out = None if args.out is None else cli.open_output(parser, args, name, [f"{name}.txt"], argv)

    ours = {name: {"risk_estimator": name} for name in ESTIMATOR_NAMES}
    ours["exact, sampled"] = {"risk_estimator": "exact", "object_motion": "sampled"}
    ours["(no risk)"] = {"estimator": "none"}
    ours["exact, 4 objects"] = {"risk_estimator": "exact", "scene": "four_crossing"}
    ours["(no risk), 4 objects"] = {"estimator": "none", "scene": "four_crossing"}
    envs = {name: stepper(name, args.steps) for name in REFERENCES}
    envs.update({label: stepper(ENV_ID, args.steps, **kwargs) for label, kwargs in ours.items()})
    times = step_times(envs, args.steps, args.repeat)

    scenario = Scenario.preset("low")
    lines = [
        f"RiskCrossing-v0 step beside Gymnasium's classic control, timed in the same run (numpy"
        f" {np.__version__}, gym.make with default wrappers, J = {scenario.mc_samples},"
        f" L = {scenario.grid_points}; best of {args.repeat} x {args.steps} steps)",
        "",
        f"{'reference':<22}{'env steps/s':>13}{'us/step':>10}",
    ]
    lines += [f"{name:<22}{1.0 / times[name]:>13,.0f}{1e6 * times[name]:>10.1f}" for name in REFERENCES]
    header = (
        f"{'estimator':<22}{'env steps/s':>13}{'us/step':>10}{'x CartPole':>12}{'x Pendulum':>12}"
        f"{'risk, 1 state [us]':>21}{f'risk, {args.batch} states [ms]':>24}"
    )
    lines += ["", header, "-" * len(header)]
    cartpole, pendulum = (times[name] for name in REFERENCES)
    for label in ours:
        t = times[label]
        row = f"{label:<22}{1.0 / t:>13,.0f}{1e6 * t:>10.1f}{t / cartpole:>12.2f}{t / pendulum:>12.2f}"
        if label in ESTIMATOR_NAMES:
            t_single, t_batch = risk_times(label, scenario, args.batch, args.repeat, args.near_only)
            row += f"{1e6 * t_single:>21.1f}{1e3 * t_batch:>24.2f}"
        else:
            row += f"{'-':>21}{'-':>24}"
        lines.append(row)
    verdicts = [
        f"{label} {times[label] / pendulum:.2f}x <= {limit:g}x:"
        f" {'met' if times[label] <= limit * pendulum else 'NOT met'}"
        for label, limit in TARGETS.items()
    ]
    lines += ["", "Targets (Pendulum-v1 steps per step): " + "; ".join(verdicts)]
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if out is not None:
        with out:
            (out.dir / f"{name}.txt").write_text(text)
    return text


if __name__ == "__main__":
    main()
