"""How fast is ``RiskCrossing-v0``? Env steps per risk estimator, and the risk estimators alone.

    python -m benchmarks.env_speed --repeat 10 --out docs/results/env_speed.txt
    python -m benchmarks.env_speed --repeat 10 --near-only --out docs/results/env_speed_near.txt

It prints one table (and writes it to ``--out``):

- env: steps/s and us/step of the unwrapped env under a constant action (v_ref straight ahead,
  which passes close to the object), resetting on termination; ``exact, sampled`` is the exact
  estimator with ``object_motion="sampled"``; ``(no risk)`` replaces the estimator by a stub, so
  it shows what the env costs around the risk;
- risk: one evaluation for a single ego state (us) and for a batch of B ego states (ms), numpy,
  against the object's one-step belief (Monte Carlo with the scenario's J = ``mc_samples``).

Times are the best of R repetitions (time.perf_counter), the usual way to read through noise.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np

from benchmarks import cli
from risk_env import ENV_ID, ESTIMATOR_NAMES, Scenario, make_estimator, predict
from risk_env.risk import signed_box_distance


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


def env_step_time(estimator: str, steps: int, repeat: int, object_motion: str = "paper") -> float:
    """Seconds per env step under a constant action, resetting on termination or truncation."""
    env = gym.make(
        ENV_ID, risk_estimator="exact" if estimator == "none" else estimator, object_motion=object_motion
    ).unwrapped
    if estimator == "none":
        env.estimator = _NoRisk()
    action = np.array([env.scenario.ego.v_ref, 0.0], dtype=np.float32)
    env.reset(seed=0)

    def step() -> None:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()

    for _ in range(min(steps, 50)):  # warm up
        step()
    return best_time(step, steps, repeat)


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
    parser.add_argument("--steps", type=int, default=2000, help="env steps per repetition")
    parser.add_argument("--repeat", type=int, default=5, help="repetitions; the best is shown")
    parser.add_argument("--batch", type=int, default=1000, help="ego states in the batch")
    parser.add_argument(
        "--near-only",
        action="store_true",
        help="batch only ego states whose disc meets the truncation box (default: uniform within 6 m)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="also write the table to this file (default: print only; the committed tables are"
        " docs/results/env_speed.txt and env_speed_near.txt)",
    )
    return parser


def main(argv: list[str] | None = None) -> str:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.steps < 1 or args.repeat < 1 or args.batch < 1:
        parser.error("--steps, --repeat and --batch must be >= 1")

    def show(line: str) -> None:
        print(line, flush=True)
        lines.append(line)

    lines: list[str] = []
    scenario = Scenario.preset("low")
    show(
        f"RiskCrossing-v0 speed (numpy {np.__version__}, "
        f"J = {scenario.mc_samples}, L = {scenario.grid_points}; best of {args.repeat})"
    )
    header = (
        f"{'estimator':<16}{'env steps/s':>13}{'us/step':>10}"
        f"{'risk, 1 state [us]':>21}{f'risk, {args.batch} states [ms]':>24}"
    )
    show(header)
    show("-" * len(header))
    for name in ESTIMATOR_NAMES:
        t_step = env_step_time(name, args.steps, args.repeat)
        t_single, t_batch = risk_times(name, scenario, args.batch, args.repeat, args.near_only)
        risk_cols = f"{1e6 * t_single:>21.1f}{1e3 * t_batch:>24.2f}"
        show(f"{name:<16}{1.0 / t_step:>13,.0f}{1e6 * t_step:>10.1f}{risk_cols}")
    for label, estimator, motion in (("exact, sampled", "exact", "sampled"), ("(no risk)", "none", "paper")):
        t_step = env_step_time(estimator, args.steps, args.repeat, motion)
        show(f"{label:<16}{1.0 / t_step:>13,.0f}{1e6 * t_step:>10.1f}{'-':>21}{'-':>24}")
    text = "\n".join(lines) + "\n"
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    return text


if __name__ == "__main__":
    main()
