"""Throughput of the vectorised ``RiskCrossing-v0`` beside Gymnasium's CartPole-v1 and Pendulum-v1,
timed in the same run.

    python -m benchmarks.vector_speed                        # 1, 64 and 1,024 copies, exact risk
    python -m benchmarks.vector_speed --num-envs 1,8,64 --modes vector_entry_point,sync,async
    python -m benchmarks.vector_speed --repeats 10 --out docs/results
    python -m benchmarks.vector_speed --objects 1,2,4 --modes vector_entry_point

Random actions (the same for every mode) drive the copies, with seeded variations of the scenario
(``randomize=True``) so that the batch holds states near and far from the object; sampled object
motion by default. Per row: the batch step [us], env steps/s, us per env step and that as a
multiple of one ``gym.make("CartPole-v1")`` and ``gym.make("Pendulum-v1")`` step (seeded random
actions). Each round runs every row (and the references) once, so that a busy spell of a shared
machine slows them alike; shown is each row's best round. Modes: ``vector_entry_point`` (our
batched env; up to :data:`~risk_env.envs.vector_env.SCALAR_COPIES` copies it steps them one by one in
Python floats), ``numpy`` (the same env held to its numpy path, shown up to 64 copies), Gymnasium's
``sync`` and ``async`` vector envs of single envs (up to ``--max-wrapped`` copies), and
``CartPole-v1`` (Gymnasium's own batched CartPole, for scale). The summary gives the fixed cost
(a batch step of 1 copy) and the cost per copy (from the smallest and largest batch).
``--objects``: the scenes timed by their number of objects (1: the paper's, 2: ``"two_crossing"``,
4: ``"four_crossing"``; :mod:`risk_env.scenario.scenes`); the targets are for one object. Lists are
comma-separated, as in every command. ``--out`` writes ``vector_speed.txt`` and its manifest
(:mod:`benchmarks.output`).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import risk_env
from benchmarks import cli
from benchmarks.env_speed import REFERENCES, step_times, stepper
from risk_env.scenario.scenario import Scenario
from risk_env.scenario.scenes import SCENE_NAMES

MODES = ("vector_entry_point", "numpy", "sync", "async", "CartPole-v1")
TARGETS = ((64, 100_000), (1024, 500_000))
"""Issue 15's targets for the batched env (exact risk, sampled motion): env steps/s at these
batch sizes; and a fixed cost of at most :data:`FIXED_COST` [s]."""
FIXED_COST = 100e-6
SCENES_BY_COUNT = {len(Scenario.preset(scene=name).objects): name for name in reversed(SCENE_NAMES)}
"""The scene timed for each number of objects (the first scene with that many)."""


def batch_stepper(mode: str, num_envs: int, steps: int, **env_kwargs) -> tuple[Callable[[], float], gym.Env]:
    """A function timing ``steps`` batch steps of a fresh episode (seconds per batch step) of
    ``mode`` with ``num_envs`` copies, and the env (to close)."""
    if mode == "CartPole-v1":
        env = gym.make_vec(mode, num_envs=num_envs, vectorization_mode="vector_entry_point")
    else:
        vectorization = "vector_entry_point" if mode == "numpy" else mode
        env = gym.make_vec(risk_env.ENV_ID, num_envs=num_envs, vectorization_mode=vectorization, **env_kwargs)
        if mode == "numpy":
            env.unwrapped.scalar_copies = 0
    space = env.single_action_space
    space.seed(0)
    actions = np.array([[space.sample() for _ in range(num_envs)] for _ in range(steps)])

    def run() -> float:
        env.reset(seed=0)
        start = time.perf_counter()
        for action in actions:
            env.step(action)
        return (time.perf_counter() - start) / steps

    return run, env


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.vector_speed``."""
    parser = cli.parser("vector_speed", __doc__)
    parser.add_argument(
        "--num-envs",
        action=cli.CommaList,
        type=cli.numbers_list(cli.positive_int),
        default="1,64,1024",
        help="comma list of batch sizes (copies)",
    )
    parser.add_argument(
        "--modes",
        action=cli.CommaList,
        type=cli.choices_list(MODES, "mode"),
        default="vector_entry_point,numpy,sync,CartPole-v1",
        help=f"comma list of what to time, from {', '.join(MODES)} (see above)",
    )
    parser.add_argument(
        "--estimators",
        action=cli.CommaList,
        type=cli.choices_list(risk_env.ESTIMATOR_NAMES, "estimator"),
        default="exact",
        help=f"comma list of risk estimators, from {', '.join(risk_env.ESTIMATOR_NAMES)}",
    )
    parser.add_argument(
        "--object-motion", choices=risk_env.OBJECT_MOTIONS, default="sampled", help="the object's true motion"
    )
    parser.add_argument(
        "--objects",
        action=cli.CommaList,
        type=cli.choices_list([str(c) for c in sorted(SCENES_BY_COUNT)], "object count"),
        default="1,4",
        help="comma list of objects per scene (1: paper, 2: two_crossing, 4: four_crossing)",
    )
    parser.add_argument("--steps", type=cli.positive_int, default=200, help="batch steps per run")
    parser.add_argument("--repeats", type=cli.positive_int, default=5, help="runs per row (the best is kept)")
    parser.add_argument(
        "--max-wrapped", type=cli.nonnegative_int, default=64, help="most copies for sync and async"
    )
    cli.add_output_options(
        parser,
        None,
        "also write the table to OUT/vector_speed.txt (default: print only; the committed one is in"
        " docs/results)",
    )
    return parser


def main(argv: list[str] | None = None) -> str:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.objects = [int(c) for c in args.objects]
    out = (
        None
        if args.out is None
        else cli.open_output(parser, args, "vector_speed", ["vector_speed.txt"], argv)
    )

    reference_steps = 2000
    references = {name: stepper(name, reference_steps) for name in REFERENCES}
    ref = dict.fromkeys(REFERENCES, float("inf"))
    rows: dict[tuple[str, str, int, int], float] = {}
    runners = {}
    for count in args.objects:
        for estimator in args.estimators:
            for num_envs in args.num_envs:
                for mode in args.modes:
                    if mode in ("sync", "async") and num_envs > args.max_wrapped:
                        continue
                    if mode == "numpy" and num_envs > 64:
                        continue
                    first = estimator == args.estimators[0] and count == args.objects[0]
                    if mode == "CartPole-v1" and not first:
                        continue
                    kwargs = {
                        "risk_estimator": estimator,
                        "randomize": True,
                        "object_motion": args.object_motion,
                        "scene": SCENES_BY_COUNT[count],
                    }
                    key = (mode, "-" if mode == "CartPole-v1" else estimator, count, num_envs)
                    runners[key] = batch_stepper(mode, num_envs, args.steps, **kwargs)
                    rows[key] = float("inf")
    for round_ in range(args.repeats):  # every row once per round: a busy spell slows them alike
        for name, t in step_times(references, reference_steps, 1).items():
            ref[name] = min(ref[name], t)
        for key, (run, _) in runners.items():
            rows[key] = min(rows[key], run())
        print(f"  round {round_ + 1}/{args.repeats} done", flush=True)
    for _, env in runners.values():
        env.close()
    cartpole, pendulum = (ref[name] for name in REFERENCES)

    lines = [
        f"RiskCrossing-v0 vectorised throughput beside Gymnasium's classic control, timed in the same"
        f" run (randomize=True, object_motion={args.object_motion}, random actions, {args.steps} batch"
        f" steps, best of {args.repeats})",
        "",
        "reference (gym.make, one env)   us/step",
        *(f"{name:<32}{1e6 * ref[name]:>8.1f}" for name in REFERENCES),
        "",
        f"{'mode':>20} {'estimator':>10} {'objects':>8} {'copies':>7} {'batch step [us]':>16}"
        f" {'env steps/s':>12} {'us/env step':>12} {'x CartPole':>11} {'x Pendulum':>11}",
    ]
    for (mode, estimator, count, num_envs), t in rows.items():
        per = t / num_envs
        shown = "-" if mode == "CartPole-v1" else count
        lines.append(
            f"{mode:>20} {estimator:>10} {shown:>8} {num_envs:>7} {1e6 * t:>16.1f} {1.0 / per:>12,.0f}"
            f" {1e6 * per:>12.2f} {per / cartpole:>11.3f} {per / pendulum:>11.3f}"
        )
    lines += ["", *summary(rows, args.estimators, pendulum)]
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if out is not None:
        with out:
            (out.dir / "vector_speed.txt").write_text(text)
    return text


def summary(
    rows: dict[tuple[str, str, int, int], float], estimators: list[str], pendulum: float
) -> list[str]:
    """Fixed cost and cost per copy of the batched env per estimator and number of objects, and
    issue 15's targets (one object); with several objects, their cost beside one object's."""
    out = []
    counts = sorted({c for (m, _, c, _) in rows if m != "CartPole-v1"})
    for estimator, count in ((e, c) for e in estimators for c in counts):
        for mode in ("vector_entry_point", "numpy"):
            times = {n: t for (m, e, c, n), t in rows.items() if m == mode and e == estimator and c == count}
            if not times:
                continue
            lo, hi = min(times), max(times)
            objects = f", {count} object{'s' if count > 1 else ''}"
            line = f"{mode} ({estimator}{objects}): fixed cost {1e6 * times[lo]:.1f} us (a batch of {lo})"
            line += f" = {times[lo] / pendulum:.2f} Pendulum-v1 steps"
            if hi > lo:
                per_copy = (times[hi] - times[lo]) / (hi - lo)
                line += f"; per copy {1e6 * per_copy:.2f} us (batches of {lo} and {hi})"
            single = rows.get((mode, estimator, 1, hi))
            if count > 1 and single is not None:
                line += f"; {times[hi] / single:.2f}x one object's batch step at {hi} copies"
            out.append(line)
            if mode != "vector_entry_point" or estimator != "exact" or count != 1:
                continue
            checks = []
            if 1 in times:
                ok = _verdict(times[1] <= FIXED_COST)
                checks.append(f"fixed cost {1e6 * times[1]:.0f} us <= {1e6 * FIXED_COST:.0f} us: {ok}")
            for n, rate in TARGETS:
                if n in times:
                    got = n / times[n]
                    checks.append(f"{n} copies {got:,.0f} >= {rate:,} env steps/s: {_verdict(got >= rate)}")
            if checks:
                out.append("Targets: " + "; ".join(checks))
    return out


def _verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


if __name__ == "__main__":
    main()
