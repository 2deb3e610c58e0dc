"""The intersection's frontier drawn from runs already made: goal rate against collision rate.

    python -m benchmarks.highway_frontier_runs --runs docs/results/highway/restart/40s_200 \\
        docs/results/highway/restart/40s_200_smpc docs/results/highway/hardstop/40s_200_idm \\
        --out results/highway/frontier_runs

Reads the summary (``NAME.csv``, checked against the SHA-256 its manifest recorded) and manifest
(``NAME.manifest.json``) of each run of
``highway_intersection`` or ``highway_frontier`` in ``--runs`` (one folder each) and draws their
agents on one frontier (:func:`benchmarks.highway_frontier.draw_frontier`), so that runs of their
own options (the RMPC's, each SMPC budget's, the IDM's) are set side by side without running them
again. Points are comparable only on the same episodes: every run must have driven the same
environment, seeds, duration, spawn probability and initial vehicles (else an error naming the
setting and the runs); an agent (with its predictor) found in two runs is drawn once if its outcomes
agree there (the IDM beside each planner), and is an error if they do not, unless a label
(``--runs DIR=LABEL``) tells the runs' agents apart (the RMPC with and without an option). Outputs in
``--out``: ``frontier_runs.png``, ``frontier_runs.md`` (the table, which agents beat the IDM, and
each run's command and commit) and ``frontier_runs.csv`` (the runs' summary rows, each with its
folder).
"""

from __future__ import annotations

import argparse
import csv
import functools
import hashlib
import json
from pathlib import Path
from typing import Any

from benchmarks import cli, highway_intersection
from benchmarks.highway_frontier import publish, title, variant_tag, verdicts, who
from benchmarks.highway_tables import RATES, rate_ci
from benchmarks.sampled_rows import wilson

FILES = ("frontier_runs.png", "frontier_runs.md", "frontier_runs.csv")
"""The files a run writes in ``--out``."""
SETS = ("intersection", "frontier")
"""The output sets whose summaries this draws."""
WORLD = ("env", "seed", "episodes", "duration", "spawn_probability", "initial_vehicles")
"""The options that make two runs' episodes the same episodes."""
SAME = (
    "episodes",
    "goal_rate",
    "collision_rate",
    "ego_into_vehicle_rate",
    "vehicle_into_ego_rate",
    "deadlock_rate",
)
"""The outcomes by which an agent found in two runs is the same agent (drawn once), or not (an error):
those that both runs counted."""
TEXT_FIELDS = frozenset({"agent", "predictor", "label", "run", "variant"})
"""Summary columns kept as text (the others are numbers, or empty)."""


class RunsError(ValueError):
    """Runs that cannot be drawn together (the message names the setting and the folders)."""


def run_folder(text: str) -> tuple[Path, str]:
    """``type=`` of ``DIR`` or ``DIR=LABEL``: a folder that exists and the label of its agents
    ("" for none)."""
    folder, _, label = text.partition("=")
    if "=" in text and not label.strip():
        raise argparse.ArgumentTypeError(f"an empty label after '=': {text!r}")
    if not folder or not Path(folder).is_dir():
        raise argparse.ArgumentTypeError(f"not a folder: {folder!r}")
    return Path(folder), label.strip()


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.highway_frontier_runs``."""
    parser = cli.parser("highway_frontier_runs", __doc__)
    parser.add_argument(
        "--runs",
        type=run_folder,
        metavar="DIR[=LABEL]",
        nargs="+",
        required=True,
        help="run folders of highway_intersection or highway_frontier, each with an optional label that"
        " tells its agents from the same agents of other runs (default: none, required)",
    )
    cli.add_output_options(
        parser, Path("results/highway/frontier_runs"), "folder for the figure, the table and the CSV"
    )
    return parser


def _number(text: str) -> Any:
    if text == "":
        return ""
    try:
        return float(text)
    except ValueError:
        return text


def read_run(folder: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The manifest and the summary rows (numbers as floats, each with its ``run`` folder) of the one
    run of :data:`SETS` in ``folder``."""
    found = [
        folder / f"{name}.manifest.json" for name in SETS if (folder / f"{name}.manifest.json").is_file()
    ]
    if len(found) != 1:
        what = "no run" if not found else "two runs"
        raise RunsError(
            f"{folder}: {what} of highway_intersection or highway_frontier (a NAME.manifest.json)"
        )
    manifest = json.loads(found[0].read_text())
    summary = folder / f"{manifest['set']}.csv"
    if not summary.is_file():
        raise RunsError(f"{folder}: {summary.name} is missing (its manifest names it)")
    recorded = manifest.get("files", {}).get(summary.name, {}).get("sha256")
    if recorded is not None and hashlib.sha256(summary.read_bytes()).hexdigest() != recorded:
        raise RunsError(
            f"{folder}: {summary.name} is not the file its run wrote (its SHA-256 is not the manifest's)"
        )
    with open(summary, newline="") as f:
        rows = [
            {"predictor": ""}  # summaries made before --predictor have none
            | {k: v if k in TEXT_FIELDS else _number(v) for k, v in row.items()}
            | {"run": str(folder)}
            for row in csv.DictReader(f)
        ]
    if not rows:
        raise RunsError(f"{folder}: {summary.name} has no agent")
    return manifest, [with_intervals(row) for row in rows]


def with_intervals(row: dict[str, Any]) -> dict[str, Any]:
    """``row`` with the Wilson interval of each of its rates that has none (summaries made before the
    goal's interval was reported), from the rate and the episode count."""
    out = dict(row)
    for key in RATES:
        rate = row.get(f"{key}_rate", "")
        if rate != "" and row.get(f"{key}_ci_low", "") == "":
            n = int(row["episodes"])
            out[f"{key}_ci_low"], out[f"{key}_ci_high"] = wilson(round(float(rate) * n), n)
    return out


@functools.cache
def _intersection_parser() -> argparse.ArgumentParser:
    """``highway_intersection``'s command line, for its defaults (built once)."""
    return highway_intersection.build_parser()


def world(manifest: dict[str, Any]) -> dict[str, Any]:
    """The :data:`WORLD` settings of a run (those its manifest lacks, or has as None, at the
    command's defaults: runs made before ``--duration`` drove highway-env's 13 s)."""
    defaults = _intersection_parser()
    options = manifest.get("options", {})
    values = {key: options.get(key) for key in WORLD}
    return {key: defaults.get_default(key) if value is None else value for key, value in values.items()}


def gather(runs: list[Path | tuple[Path, str]]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The manifests and the summary rows of ``runs`` (folders, or ``(folder, label)``: the label is
    each of its rows' ``variant``), checked to share their episodes and to name every agent (with its
    predictor and label) once (raises :class:`RunsError`)."""
    labelled = [(run, "") if isinstance(run, Path) else (Path(run[0]), run[1]) for run in runs]
    folders = [folder for folder, _ in labelled]
    if len({p.resolve() for p in folders}) != len(folders):
        raise RunsError(f"a folder is named twice: {' '.join(map(str, folders))}")
    manifests, rows = [], []
    for folder, label in labelled:
        manifest, summary = read_run(folder)
        manifests.append(manifest | {"folder": str(folder), "variant": label})
        rows += [row | {"variant": label} for row in summary]
    first = world(manifests[0])
    for manifest in manifests[1:]:
        other = world(manifest)
        for key in WORLD:
            if other[key] != first[key]:
                raise RunsError(
                    f"the runs drove other episodes: {key} {first[key]!r} in {manifests[0]['folder']},"
                    f" {other[key]!r} in {manifest['folder']}"
                )
    kept: dict[tuple[str, str, str], dict[str, Any]] = {}
    for row in rows:
        key = (row["agent"], row["predictor"], row["variant"])
        if key not in kept:
            kept[key] = row
        elif any(row[k] != kept[key][k] for k in SAME if k in row and k in kept[key]):
            who = f"{key[0]} ({key[1] or 'no predictor'})" + variant_tag(key[2])
            raise RunsError(
                f"{who} differs in two runs: {kept[key]['run']} and {row['run']} (a label, DIR=LABEL,"
                " tells them apart)"
            )
    return manifests, list(kept.values())


def _cell(s: dict[str, Any], key: str, form: str) -> str:
    """``s[key]`` formatted, "-" where it is NaN, "n/a" where the run did not count it."""
    value = s.get(key, "")
    if value == "":
        return "n/a"
    return "-" if value != value else format(value, form)


def markdown(manifests: list[dict[str, Any]], rows: list[dict[str, Any]], command: str) -> str:
    """The frontier's table and the verdicts against the IDM."""
    w = world(manifests[0])
    seeds = f"{int(w['seed'])}..{int(w['seed'] + w['episodes'] - 1)}"
    lines = [
        f"`{command}`",
        "",
        f"{w['env']}, duration {w['duration']:g} s, spawn probability {w['spawn_probability']:g},"
        f" {w['initial_vehicles']} initial vehicles, seeds {seeds} (the same episodes in every run)."
        " Rates: % [Wilson 95 % interval].",
        "",
        "| agent | run | N | goal | collisions | ego drove into a vehicle | deadlocks | time to goal [s] |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for s in rows:
        lines.append(
            f"| {who(s)} | `{s['run']}` | {int(s['episodes'])} | {rate_ci(s, 'goal')} |"
            f" {rate_ci(s, 'collision')} | {rate_ci(s, 'ego_into_vehicle')} | {_cell(s, 'deadlock', '.0f')} |"
            f" {_cell(s, 'time_to_goal_s', '.1f')} |"
        )
    lines.append(verdicts(rows))
    return "\n".join(lines) + "\n"


def provenance(manifests: list[dict[str, Any]]) -> str:
    """Each run's folder, command and commit (kept out of the tables a docs page includes)."""
    lines = ["The runs:", ""]
    for m in manifests:
        commit = (m.get("git_commit") or "")[:7] or "unknown code"
        lines.append(
            f"- `{m['folder']}`{variant_tag(m.get('variant', ''))} (run on {commit}): `{m['command']}`"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        manifests, rows = gather(args.runs)
    except RunsError as error:
        parser.error(f"--runs: {error}")
    out = cli.open_output(parser, args, "frontier_runs", FILES, argv)
    with out:
        with open(out.dir / "frontier_runs.csv", "w", newline="") as f:
            fields = list(dict.fromkeys(k for row in rows for k in row))
            writer = csv.DictWriter(f, fieldnames=fields)
            writer.writeheader()
            writer.writerows(rows)
        w = world(manifests[0])
        episodes = (w["env"], w["duration"], w["spawn_probability"], w["seed"], w["episodes"])
        heading = title(*episodes, note=f"; {len(manifests)} runs")
        tables = markdown(manifests, rows, out.command_line.strip())
        text = publish(out.dir, "frontier_runs", tables, rows, heading, provenance(manifests))
    print(text)
    return rows


if __name__ == "__main__":
    main()
