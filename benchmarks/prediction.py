"""How well each predictor predicts highway-env's traffic on seeded episodes of ``intersection-v2``.

    python -m benchmarks.prediction --episodes 10                 # a quick look
    python -m benchmarks.prediction --episodes 200 --out docs/results/prediction

Each episode (seeds S..S+E-1) runs ``intersection-v2`` (:data:`~risk_env.highway.adapter.INTERSECTION_CONFIG`:
T = 0.5 s) for ``--duration`` seconds with the ego driven by highway-env's own IDM
(:class:`~risk_env.highway.IDMEgo`, to ``"o1"``), so that the traffic is highway-env's; the episode
runs on when the ego arrives or crashes. At every step each predictor (``--predictors``) predicts
every vehicle from its measurement (:func:`~risk_env.highway.vehicle_measurement`; the ego's
among them, since the others react to it) over 6 steps (3 s), and each other vehicle's prediction
is scored against where it really is 1..6 steps later (while it is still on the road):

- ``constant``: the paper's (:class:`~risk_env.prediction.ConstantPredictor`, ``--uncertainty``
  level, speeds up to 40 m/s);
- ``lane``: :class:`~risk_env.highway.LanePredictor` on the episode's road network;
- ``lane+signal``: the same, also given each vehicle's turn signal (highway-env's
  ``observe_intentions``: the unit vector to its destination).

Per predictor, phase (the vehicle's lane at the prediction: ``approach`` to, ``junction`` in,
``exit`` from the intersection; ``all`` of them) and horizon, ``prediction.csv`` holds:
``ade_m``, the mean distance from the true position to the mean of the most likely mode;
``coverage``, the share of true positions inside the truncation box (in its own frame) of some
mode of weight at least ``--mode-threshold`` (the most likely mode when none is);
``box_area_m2``, the mean total area of those boxes; ``area_99_m2``, the area of the smallest
world-axis square centred on the most likely mode's mean that holds 99 % of the true positions
(the size a box needs to cover them, for any predictor); ``route_brier``, the Brier score of the
route weights (:attr:`~risk_env.highway.lanes.LaneMode.routes`, each route taken when its nodes
lie in the order of the vehicle's own route) against the route taken, at the prediction (empty
for ``constant``); ``samples``, and ``fallbacks``, the predictions that fell back to the constant
predictor (off the road). Vehicles that have crashed (at the prediction or at the scored step)
are obstacles at rest, scored apart in the phase ``crashed`` (not in ``all``). ``prediction.md``
holds the table at 1.5 s and 3 s, the command, and ``prediction.png``: both predictors' boxes
(weights as opacity) at three moments of the first episode.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cli
from benchmarks.sweep import run_sweep

PREDICTORS = ("constant", "lane", "lane+signal")
PHASES = ("all", "approach", "junction", "exit", "crashed")
STEPS = 6
"""Prediction steps scored (3 s at T = 0.5 s)."""
CHUNK = 2
"""Episodes per pool job."""
_CACHE: dict[tuple[Any, ...], Any] = {}


# ---------------------------------------------------------------------- recording
def phase_of(lane_index: tuple[str, str, int]) -> str:
    """``approach`` (o -> ir), ``junction`` (ir -> il) or ``exit`` (il -> o) of an intersection lane."""
    start = lane_index[0]
    return "approach" if start.startswith("o") else "junction" if start.startswith("ir") else "exit"


def route_nodes(route: Any) -> tuple[str, ...]:
    """A highway-env route (list of lane indices) as its nodes, e.g. ``("o0", "ir0", "il1", "o1")``."""
    if not route:
        return ()
    return (route[0][0], *(index[1] for index in route))


def record_episode(env: Any, seed: int) -> list[dict[str, Any]]:
    """One episode of ``env`` (config ``duration`` set) driven by :class:`IDMEgo`: per step, every
    vehicle's id, measurement, lane, crash flag, turn signal and route (read here for scoring only)."""
    from risk_env.highway import IDMEgo, vehicle_measurement

    ego = IDMEgo(env)
    obs, _ = env.reset(seed=seed)
    ego.reset()
    base = env.unwrapped
    steps: list[dict[str, Any]] = []
    while True:
        action, _ = ego.predict(obs)
        vehicles = list(base.road.vehicles)
        steps.append(
            {
                "ids": [id(v) for v in vehicles],
                "ego": [v is base.vehicle for v in vehicles],
                "m": np.array([vehicle_measurement(v) for v in vehicles]),
                "lane": [tuple(v.lane_index) for v in vehicles],
                "crashed": np.array([bool(v.crashed) for v in vehicles]),
                "signal": np.array([v.destination_direction for v in vehicles], dtype=float),
                "route": [route_nodes(getattr(v, "route", None)) for v in vehicles],
            }
        )
        obs, _, _, truncated, _ = env.step(action)
        if truncated:
            return steps


# ---------------------------------------------------------------------- scoring
def _inside(mode: Any, n: int, point: np.ndarray) -> tuple[bool, float]:
    """Whether ``point`` lies in ``mode``'s truncation box at step ``n`` (in its frame), and the
    box's area [m^2]."""
    from risk_env.models.frame import to_frame

    b = mode.beliefs[n]
    along, across = to_frame(point[0] - float(b.x), point[1] - float(b.y), float(b.frame))
    hx, hy = float(b.half_x), float(b.half_y)
    return bool(abs(along) <= hx and abs(across) <= hy), 4.0 * hx * hy


def brier(mixture: Any, taken: tuple[str, ...]) -> float:
    """The Brier score of ``mixture``'s route weights against the route ``taken`` (its nodes); NaN
    when its modes carry no routes."""
    routes = [route for mode in mixture for route in getattr(mode, "routes", ())]
    if not routes:
        return float("nan")
    joined = ">" + ">".join(taken) + ">"
    return float(sum((w - float((">" + label + ">") in joined)) ** 2 for label, w in routes))


def true_routes(steps: list[dict[str, Any]]) -> dict[int, tuple[str, ...]]:
    """Each vehicle's route as its nodes: its route when first seen (highway-env drops a lane from
    it as the vehicle ends that lane), after the node its lane then started from."""
    out: dict[int, tuple[str, ...]] = {}
    for step in steps:
        for vid, lane, nodes in zip(step["ids"], step["lane"], step["route"], strict=True):
            if vid not in out:
                out[vid] = (lane[0], *nodes) if nodes and lane[1] == nodes[0] else nodes
    return out


def score_episode(
    steps: list[dict[str, Any]], predictors: dict[str, Any], threshold: float
) -> dict[str, np.ndarray]:
    """Per predictor, the scored samples of one recorded episode: columns ``phase`` (index into
    :data:`PHASES`), ``n``, ``err``, ``covered``, ``area``, ``chebyshev``, ``brier``, ``fallback``."""
    from risk_env.highway.lanes import LaneMode

    out: dict[str, list[tuple]] = {name: [] for name in predictors}
    where = [{vid: k for k, vid in enumerate(step["ids"])} for step in steps]
    taken = true_routes(steps)
    for t, step in enumerate(steps):
        for name, predictor in predictors.items():
            signals = step["signal"] if name == "lane+signal" else None
            kwargs = {"signals": signals} if signals is not None else {}
            mixtures = predictor.predict_scene(step["m"], STEPS, **kwargs)
            for k, vid in enumerate(step["ids"]):
                if step["ego"][k]:
                    continue
                mixture = mixtures[k]
                best = mixture.most_likely()
                kept = mixture.above(threshold)
                fallback = name != "constant" and not isinstance(best, LaneMode)
                score = brier(mixture, taken[vid]) if name != "constant" else float("nan")
                phase = PHASES.index(phase_of(step["lane"][k]))
                for n in range(1, STEPS + 1):
                    if t + n >= len(steps) or vid not in where[t + n]:
                        continue
                    j = where[t + n][vid]
                    truth = steps[t + n]["m"][j, :2]
                    crashed = bool(step["crashed"][k] or steps[t + n]["crashed"][j])
                    mean = np.array([float(best.beliefs.x[n]), float(best.beliefs.y[n])])
                    inside = [_inside(mode, n, truth) for mode in kept]
                    out[name].append(
                        (
                            PHASES.index("crashed") if crashed else phase,
                            n,
                            float(np.hypot(*(truth - mean))),
                            any(i for i, _ in inside),
                            sum(a for _, a in inside),
                            float(np.max(np.abs(truth - mean))),
                            score,
                            fallback,
                        )
                    )
    keys = ("phase", "n", "err", "covered", "area", "chebyshev", "brier", "fallback")
    return {
        name: {key: np.array([row[i] for row in rows]) for i, key in enumerate(keys)} if rows else {}
        for name, rows in out.items()
    }


def make_predictors(names: list[str], env: Any, uncertainty: str) -> dict[str, Any]:
    """The predictors ``names`` for ``env`` (its road network, its step)."""
    from risk_env.highway import LanePredictor, highway_scenario, policy_period
    from risk_env.prediction import ConstantPredictor

    out: dict[str, Any] = {}
    for name in names:
        if name == "constant":
            out[name] = ConstantPredictor(highway_scenario(env, uncertainty))
        else:
            out[name] = LanePredictor(env.unwrapped.road.network, policy_period(env))
    return out


def run_chunk(job: tuple[list[int], argparse.Namespace]) -> dict[str, dict[str, np.ndarray]]:
    """Record and score the episodes ``seeds`` (a pool job; the env kept per process)."""
    seeds, args = job
    key = ("env", args.duration)
    if key not in _CACHE:
        from risk_env.highway import make_intersection_env

        _CACHE[key] = make_intersection_env(duration=args.duration)
    env = _CACHE[key]
    parts: dict[str, list[dict[str, np.ndarray]]] = defaultdict(list)
    for seed in seeds:
        steps = record_episode(env, seed)
        predictors = make_predictors(args.predictors, env, args.uncertainty)
        for name, samples in score_episode(steps, predictors, args.mode_threshold).items():
            if samples:
                parts[name].append(samples)
    return {
        name: {k: np.concatenate([p[k] for p in chunks]) for k in chunks[0]} for name, chunks in parts.items()
    }


# ---------------------------------------------------------------------- tables
def summarise(samples: dict[str, dict[str, np.ndarray]], dt: float) -> list[dict[str, Any]]:
    """The rows of ``prediction.csv`` (module docstring)."""
    rows = []
    for name, s in samples.items():
        for phase in PHASES:
            if phase == "all":
                chosen = s["phase"] != PHASES.index("crashed")
            else:
                chosen = s["phase"] == PHASES.index(phase)
            for n in range(1, STEPS + 1):
                mask = chosen & (s["n"] == n)
                count = int(mask.sum())
                if not count:
                    continue
                first = mask & (s["n"] == n)
                scores = s["brier"][first]
                scores = scores[~np.isnan(scores)]
                rows.append(
                    {
                        "predictor": name,
                        "phase": phase,
                        "horizon_s": round(n * dt, 6),
                        "ade_m": float(s["err"][mask].mean()),
                        "coverage": float(s["covered"][mask].mean()),
                        "box_area_m2": float(s["area"][mask].mean()),
                        "area_99_m2": float((2 * np.quantile(s["chebyshev"][mask], 0.99)) ** 2),
                        "route_brier": float(scores.mean()) if scores.size else "",
                        "samples": count,
                        "fallbacks": int(s["fallback"][mask].sum()),
                    }
                )
    return rows


def _cell(value: Any, digits: int) -> str:
    return "-" if value == "" else f"{value:.{digits}f}"


def markdown(rows: list[dict[str, Any]], args: argparse.Namespace, command: str, wall: float) -> str:
    """The table of ``rows`` at 1.5 s and 3 s, with the settings and the command."""
    lines = [
        f"`{command}`",
        "",
        f"intersection-v2 (INTERSECTION_CONFIG, T = 0.5 s),"
        f" seeds {args.seed}..{args.seed + args.episodes - 1}"
        f" ({args.episodes} episodes of {args.duration:g} s, ego: highway-env's IDM); mode threshold"
        f" w_min = {args.mode_threshold:g}; constant predictor at the {args.uncertainty!r} level."
        f" Wall time {wall:.0f} s.",
        "",
        "| predictor | phase | horizon [s] | ADE [m] | coverage | box area [m²] | area 99 % [m²] |"
        " route Brier | samples | fallbacks |",
        "| " + " | ".join(["---"] * 10) + " |",
    ]
    for r in rows:
        if r["horizon_s"] not in (1.5, 3.0):
            continue
        lines.append(
            f"| {r['predictor']} | {r['phase']} | {r['horizon_s']:g} | {r['ade_m']:.2f} |"
            f" {100 * r['coverage']:.1f}% | {r['box_area_m2']:.0f} | {r['area_99_m2']:.0f} |"
            f" {_cell(r['route_brier'], 3)} | {r['samples']} | {r['fallbacks']} |"
        )
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.prediction``."""
    parser = cli.parser("prediction", __doc__)
    parser.add_argument("--episodes", type=int, default=200, help="seeded episodes")
    parser.add_argument("--seed", type=int, default=0, help="first seed")
    parser.add_argument("--duration", type=float, default=20.0, help="episode length [s]")
    parser.add_argument(
        "--predictors", default="constant,lane", help=f"comma list of {', '.join(PREDICTORS)}"
    )
    parser.add_argument(
        "--mode-threshold",
        type=float,
        default=0.05,
        help="w_min: a mode's box counts when its weight is at least this (the robust planner's threshold)",
    )
    parser.add_argument(
        "--uncertainty",
        choices=("low", "medium", "high"),
        default="low",
        help="the constant predictor's level",
    )
    parser.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    parser.add_argument(
        "--figure", action=argparse.BooleanOptionalAction, default=True, help="draw prediction.png"
    )
    parser.add_argument("--out", type=Path, default=Path("results/prediction"), help="output folder")
    return parser


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.predictors = cli.comma_list(args.predictors)
    unknown = [p for p in args.predictors if p not in PREDICTORS]
    if unknown or not args.predictors:
        parser.error(f"unknown predictor(s) {unknown}; expected a comma list of {', '.join(PREDICTORS)}")
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    if not (args.duration > 0 and np.isfinite(args.duration)):
        parser.error("--duration must be > 0 [s]")
    if not (0.0 <= args.mode_threshold <= 1.0):
        parser.error("--mode-threshold must lie in [0, 1]")
    return args


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    args = parse_args(argv)
    command = "python -m benchmarks.prediction " + " ".join(sys.argv[1:] if argv is None else argv)
    t0 = time.perf_counter()
    seeds = list(range(args.seed, args.seed + args.episodes))
    jobs = [(seeds[i : i + CHUNK], args) for i in range(0, len(seeds), CHUNK)]
    chunks = run_sweep(run_chunk, jobs, workers=args.workers, desc="intersection-v2 episodes")
    samples = {
        name: {
            k: np.concatenate([c[name][k] for c in chunks if name in c])
            for k in next(c[name] for c in chunks if name in c)
        }
        for name in args.predictors
        if any(name in c for c in chunks)
    }
    rows = summarise(samples, 0.5)
    wall = time.perf_counter() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "prediction.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    text = markdown(rows, args, command, wall)
    if args.figure:
        from benchmarks.prediction_figure import draw

        draw(
            args.seed,
            args.duration,
            args.predictors,
            args.uncertainty,
            args.mode_threshold,
            args.out / "prediction.png",
        )
        text += "\n![Both predictors' boxes](prediction.png)\n"
    (args.out / "prediction.md").write_text(text)
    print(text)
    return rows


if __name__ == "__main__":
    main()
