"""How well each predictor predicts highway-env's traffic on seeded episodes of ``intersection-v2``.

    python -m benchmarks.prediction --episodes 10 --predictors constant,lane,lane+signal   # a quick look
    python -m benchmarks.prediction --episodes 200 --seed 1000 --predictors constant,lane,lane+signal \\
        --workers 1 --out docs/results/prediction

Each episode (seeds S..S+E-1) runs ``intersection-v2``
(:data:`~risk_env.highway.adapter.INTERSECTION_CONFIG`: T = 0.5 s) for ``--duration`` seconds with
the ego driven by highway-env's own IDM (:class:`~risk_env.highway.IDMEgo`, to ``"o1"``), so that
the traffic is highway-env's; the episode runs on when the ego arrives or crashes. At every step
each predictor (``--predictors``) predicts every vehicle from its measurement
(:func:`~risk_env.highway.vehicle_measurement`; the ego's among them, since the others react to it)
over 6 steps (3 s), and each other vehicle's prediction is scored against where it really is 1..6
steps later (while it is still on the road):

- ``constant``: the paper's (:class:`~risk_env.prediction.ConstantPredictor`, ``--uncertainty``
  level, speeds up to 40 m/s);
- ``lane``: :class:`~risk_env.highway.LanePredictor` on the episode's road network;
- ``lane+signal``: the same, also given each vehicle's turn signal (highway-env's
  ``observe_intentions``: the unit vector to its destination);
- ``lane+interval``: the lane predictor with the interval prediction over highway-env's IDM
  parameters along the lane (``longitudinal="interval"``; the ego is one of the scene's road users).

Per predictor, phase (the vehicle's lane at the prediction: ``approach`` to, ``junction`` in,
``exit`` from the intersection; ``all`` of them) and horizon, ``prediction.csv`` holds:
``ade_m``, the mean distance from the true position to the mean of the most likely mode;
``coverage``, the share of true positions inside the truncation box (in its own frame) of some
mode of weight at least ``--mode-threshold`` (the most likely mode when none is);
``box_area_m2``, the mean total area of those boxes; ``area_99_m2``, the area of the smallest
world-axis square centred on the most likely mode's mean that holds 99 % of the true positions
(the size a box needs to cover them, for any predictor); ``route_brier``, the Brier score of the
route weights (:attr:`~risk_env.highway.lanes.predictor.LaneMode.routes`, each route taken when its nodes
lie in the order of the vehicle's own route) against the route taken, at the prediction (empty
for ``constant``); ``samples``, and ``fallbacks``, the predictions that fell back to the constant
predictor (off the road). Vehicles that have crashed (at the prediction or at the scored step)
are obstacles at rest, scored apart in the phase ``crashed`` (not in ``all``); the phase
``reversing`` scores again the samples of ``all`` whose vehicle rolls back by the scored step
(highway-env's IDM brakes through a stop when its leader is too close). ``prediction.md``
holds the table at 1.5 s and 3 s, the command, and ``prediction.png``: both predictors' boxes
(weights as opacity) at three moments of the first episode.
"""

from __future__ import annotations

import argparse
import csv
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import cli
from benchmarks.highway_agents import add_interval_option
from benchmarks.prediction_figure import draw
from benchmarks.prediction_samples import KEYS, PHASES, STEPS, make_predictors, record_episode, score_episode
from benchmarks.sweep import run_sweep
from risk_env.scenario.scenario import UNCERTAINTY_PRESETS

PREDICTORS = ("constant", "lane", "lane+signal", "lane+interval")
"""The predictors by ``--predictors`` name (module docstring)."""
FILES = ("prediction.csv", "prediction.md")
"""The files a run writes in ``--out`` (and ``prediction.png`` unless ``--no-figures``)."""
DT = 0.5
"""The step [s] of :data:`~risk_env.highway.adapter.INTERSECTION_CONFIG` (8 frames at 16 Hz)."""
CHUNK = 2
"""Episodes per pool job."""
_CACHE: dict[tuple[Any, ...], Any] = {}


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
        predictors = make_predictors(args.predictors, env, args.uncertainty, args.interval)
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
        for phase in (*PHASES, "reversing"):
            if phase in ("all", "reversing"):
                chosen = s["phase"] != PHASES.index("crashed")
                chosen = chosen & s["reversing"] if phase == "reversing" else chosen
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


def _value(rows: list[dict[str, Any]], predictor: str, phase: str, horizon: float, key: str) -> Any:
    found = [
        r[key] for r in rows if (r["predictor"], r["phase"], r["horizon_s"]) == (predictor, phase, horizon)
    ]
    return found[0] if found and found[0] != "" else None


def targets(rows: list[dict[str, Any]]) -> list[str]:
    """Each route-aware predictor against the bounds the benchmark checks, relative to ``constant``
    (a Markdown table; empty without ``constant``)."""
    horizons = sorted({r["horizon_s"] for r in rows})
    if not horizons or _value(rows, "constant", "all", horizons[-1], "ade_m") is None:
        return []
    last = horizons[-1]
    header = (
        f"| predictor | lowest coverage over the horizons (target >= 99 %) | box area at {last:g} s /"
        f" constant's area 99 % (<= 1/3) | ADE at {last:g} s / constant's (<= 0.75) | the same in the"
        " junction (<= 0.5) | route Brier, junction / exit (<= 0.15) | route Brier, approach |"
    )
    lines = [header, "| " + " | ".join(["---"] * 7) + " |"]

    def ratio(a: Any, b: Any) -> str:
        return "-" if a is None or not b else f"{a / b:.2f}"

    def brier(predictor: str, phase: str) -> str:
        value = _value(rows, predictor, phase, last, "route_brier")
        return "-" if value is None else f"{value:.3f}"

    for name in sorted({r["predictor"] for r in rows} - {"constant"}):
        coverage = [_value(rows, name, "all", h, "coverage") for h in horizons]
        lowest = min(c for c in coverage if c is not None)
        area = ratio(
            _value(rows, name, "all", last, "box_area_m2"),
            _value(rows, "constant", "all", last, "area_99_m2"),
        )
        ade = ratio(_value(rows, name, "all", last, "ade_m"), _value(rows, "constant", "all", last, "ade_m"))
        inside = ratio(
            _value(rows, name, "junction", last, "ade_m"), _value(rows, "constant", "junction", last, "ade_m")
        )
        lines.append(
            f"| {name} | {100 * lowest:.2f} % | {area} | {ade} | {inside} |"
            f" {brier(name, 'junction')} / {brier(name, 'exit')} | {brier(name, 'approach')} |"
        )
    return lines


def markdown(rows: list[dict[str, Any]], args: argparse.Namespace, command: str, wall: float) -> str:
    """The command and the settings, the targets (section ``targets`` for the docs' snippets), then
    the table of ``rows`` at 1.5 s and 3 s (section ``table``)."""
    lines = [
        "<!-- --8<-- [start:targets] -->",
        f"`{command}`",
        "",
        f"intersection-v2 (INTERSECTION_CONFIG, T = 0.5 s),"
        f" seeds {args.seed}..{args.seed + args.episodes - 1}"
        f" ({args.episodes} episodes of {args.duration:g} s, ego: highway-env's IDM); mode threshold"
        f" w_min = {args.mode_threshold:g}; constant predictor at the {args.uncertainty!r} level."
        f"{' Interval switches on: ' + ', '.join(args.interval) + '.' if args.interval else ''}"
        f" Wall time {wall:.0f} s.",
        "",
        *targets(rows),
        "<!-- --8<-- [end:targets] -->",
        "",
        "<!-- --8<-- [start:table] -->",
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
    lines.append("<!-- --8<-- [end:table] -->")
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.prediction``."""
    parser = cli.parser("prediction", __doc__)
    parser.add_argument("--episodes", type=cli.positive_int, default=200, help="seeded episodes")
    parser.add_argument("--seed", type=cli.nonnegative_int, default=0, help="first seed")
    parser.add_argument("--duration", type=cli.positive_float, default=20.0, help="episode length [s]")
    parser.add_argument(
        "--predictors",
        type=cli.choices_list(PREDICTORS, "predictor"),
        default="constant,lane",
        help=f"comma list of {', '.join(PREDICTORS)}",
    )
    parser.add_argument(
        "--mode-threshold",
        type=cli.unit_interval_closed,
        default=0.05,
        help="w_min: a mode's box counts when its weight is at least this (the robust planner's threshold)",
    )
    parser.add_argument(
        "--uncertainty", choices=UNCERTAINTY_PRESETS, default="low", help="the constant predictor's level"
    )
    add_interval_option(parser)
    parser.add_argument("--no-figures", action="store_true", help="skip prediction.png")
    parser.add_argument(
        "--workers", type=cli.positive_int, default=None, help="processes (default: all cores)"
    )
    cli.add_output_options(parser, Path("results/prediction"), "output folder", resume=True)
    return parser


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    parser = build_parser()
    args = parser.parse_args(argv)
    files = FILES if args.no_figures else (*FILES, "prediction.png")
    out = cli.open_output(parser, args, "prediction", files, argv)
    seeds = list(range(args.seed, args.seed + args.episodes))
    jobs = [(seeds[i : i + CHUNK], args) for i in range(0, len(seeds), CHUNK)]
    with out:
        t0 = time.perf_counter()
        chunks = run_sweep(
            run_chunk, jobs, workers=args.workers, desc="intersection-v2 episodes", store=out.store
        )
        samples = {
            name: {key: np.concatenate([c[name][key] for c in chunks if name in c]) for key in KEYS}
            for name in args.predictors
            if any(name in c for c in chunks)
        }
        rows = summarise(samples, DT)
        wall = time.perf_counter() - t0
        with open(out.dir / "prediction.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
        text = markdown(rows, args, out.command_line.strip(), wall)
        if not args.no_figures:
            from risk_env.highway import make_intersection_env

            env = make_intersection_env(duration=args.duration)
            steps = record_episode(env, args.seed)
            predictors = make_predictors(args.predictors, env, args.uncertainty, args.interval)
            network = env.unwrapped.road.network
            figure = out.dir / "prediction.png"
            draw(steps, network, predictors, STEPS, args.mode_threshold, args.seed, figure)
            text += "\n![Both predictors' boxes over one episode](prediction.png)\n"
        (out.dir / "prediction.md").write_text(text)
    print(text)
    return rows


if __name__ == "__main__":
    main()
