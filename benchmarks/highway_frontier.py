"""The safety-progress frontier at highway-env's intersection: goal rate against collision rate.

    python -m benchmarks.highway_frontier --episodes 200 --max-solve-time inf --out results/highway/frontier
    python -m benchmarks.highway_frontier --episodes 2 --duration 3 --agents rmpc,smpc,idm \\
        --predictor constant --slots 2 --workers 1 --out results/frontier_try

Runs the agents of :mod:`benchmarks.highway_intersection` (the same options, episode runner and
tables) over the same seeds, by default the RMPC, the SMPC at the episode budgets 0.01, 0.02, 0.05
and 0.1, and highway-env's IDM, each MPC with the lane predictor and with the paper's (``--predictor
lane,constant``), and draws ``frontier.png``: every agent's goal rate against its collision rate,
each with its Wilson 95 % interval. The lane predictor's points (and its variants',
``lane+interval``) are filled, the paper's (``constant``) hollow, any other predictor's half filled;
the SMPC's budgets are joined in order of B and labelled; the shaded quadrant is where an agent
beats the IDM on both axes (a goal rate at least the IDM's with fewer collisions). Outputs in
``--out``, one output set (``--resume`` goes on after an interruption): ``frontier.png``,
``frontier.md`` (the tables and which agents beat the IDM), ``frontier.csv`` and
``frontier_episodes.csv``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from benchmarks import cli, highway_intersection
from benchmarks.agent_names import REFERENCES, parse_agent
from benchmarks.highway_agents import KINDS
from benchmarks.highway_intersection import add_options, run
from benchmarks.highway_tables import markdown, write_csvs

AGENTS = "rmpc,smpc:budget=0.01,smpc:budget=0.02,smpc:budget=0.05,smpc:budget=0.1,idm"
"""The frontier's agents by default."""
FILES = ("frontier.png", "frontier.md", "frontier.csv", "frontier_episodes.csv")
"""The files a run writes in ``--out``."""
COLOURS = {"rmpc": "tab:blue", "smpc": "tab:orange", "idm": "black", "hindsight": "tab:gray"}
MARKERS = {"rmpc": "^", "smpc": "o", "idm": "*", "hindsight": "P"}
PREDICTOR_NAMES = {"constant": "the paper's"}
"""How the legend names a predictor (others by their own name)."""
PREDICTOR_STYLE = {"lane": "-", "constant": "--"}
"""Line style of the SMPC's budget curve with each predictor (others dotted)."""
PREDICTOR_FILL = {"lane": "full", "constant": "none"}
"""Marker fill of each predictor family's points (others half filled, ``"left"``)."""


def family(predictor: str) -> str:
    """The predictor's family for the figure's marks: ``"lane"`` for the lane predictor and its
    variants (``lane+interval``, ...), else the name itself."""
    return "lane" if predictor.split("+")[0] == "lane" else predictor


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.highway_frontier``."""
    parser = cli.parser("highway_frontier", __doc__)
    add_options(parser, AGENTS, "lane,constant", Path("results/highway/frontier"))
    return parser


def parse_args(
    argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None
) -> argparse.Namespace:
    """The options, checked as :func:`benchmarks.highway_intersection.parse_args` checks them."""
    return highway_intersection.parse_args(argv, parser or build_parser())


def _rate(s: dict[str, Any], key: str) -> tuple[float, float, float]:
    """A rate and its Wilson interval's distances below and above, in %."""
    r, lo, hi = (100 * float(s[f"{key}_{part}"]) for part in ("rate", "ci_low", "ci_high"))
    return r, r - lo, hi - r


def beats(s: dict[str, Any], idm: dict[str, Any]) -> bool:
    """Whether the agent of summary row ``s`` beats the IDM's row on both axes: a goal rate at
    least the IDM's and a collision rate below it (point estimates)."""
    return s["goal_rate"] >= idm["goal_rate"] and s["collision_rate"] < idm["collision_rate"]


def variant_tag(label: str) -> str:
    """A run's label as it follows its agents' names (" [LABEL]"; "" for none)."""
    return f" [{label}]" if label else ""


def who(s: dict[str, Any]) -> str:
    """A summary row's agent, with its predictor and its run's ``variant`` label if any."""
    return s["agent"] + (f" ({s['predictor']})" if s["predictor"] else "") + variant_tag(s.get("variant", ""))


def _style(s: dict[str, Any]) -> tuple[str, str, float | None]:
    """The legend label, the marker and the budget B (None: not an SMPC on a budget alone) of a
    summary row."""
    agent = parse_agent(s["agent"], KINDS)
    pred = s["predictor"]
    note = f" ({PREDICTOR_NAMES.get(pred, pred)} predictor)" if pred else ""
    note += variant_tag(s.get("variant", ""))
    if agent.kind == "idm":
        return "IDM (highway-env)", "*", None
    if agent.kind == "hindsight":
        return "hindsight (knows the future)", "P", None
    if agent.kind == "rmpc":
        return f"RMPC{note}", "^", None
    if agent.budget is not None and agent.tolerance is None:
        return f"SMPC, episode budget B{note}", "o", agent.budget
    return f"SMPC {s['agent'].removeprefix('smpc:').removeprefix('exact:')}{note}", "D", None


VARIANT_EDGES = ("black", "tab:purple", "tab:red", "tab:olive")
"""The edge colours of labelled runs' points, one per label in the order the runs are given."""


def draw_frontier(summary: list[dict[str, Any]], path: Path, title: str) -> Path:
    """``path`` (PNG): goal rate against collision rate of every summary row, with Wilson
    intervals (see the module docstring for the marks)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10.5, 6.0))
    idm = next((s for s in summary if s["agent"] == "idm"), None)
    if idm is not None:
        c, g = 100 * idm["collision_rate"], 100 * idm["goal_rate"]
        ax.fill_between(
            [-2, c], g, 102, color="tab:green", alpha=0.1, lw=0, label="beats the IDM on both axes"
        )
    curves: dict[str, list[tuple[float, float, float]]] = {}
    tags: dict[tuple[float, float], list[float]] = {}
    labels = list(dict.fromkeys(s["variant"] for s in summary if s.get("variant")))
    edges = {label: VARIANT_EDGES[i % len(VARIANT_EDGES)] for i, label in enumerate(labels)}
    for s in summary:
        kind = s["agent"].split(":")[0]
        label, marker, budget = _style(s)
        x, x_lo, x_hi = _rate(s, "collision")
        y, y_lo, y_hi = _rate(s, "goal")
        colour = COLOURS[kind]
        ax.errorbar(x, y, xerr=[[x_lo], [x_hi]], yerr=[[y_lo], [y_hi]], fmt="none", ecolor=colour, alpha=0.35)
        if budget is not None:
            curves.setdefault((s["predictor"], s.get("variant", "")), []).append((budget, x, y))
            tags.setdefault((round(x, 6), round(y, 6)), []).append(budget)
        ax.plot(
            x,
            y,
            marker=marker,
            ms=13 if kind in REFERENCES else 8,
            ls="none",
            color=colour,
            fillstyle=PREDICTOR_FILL.get(family(s["predictor"]), "left") if s["predictor"] else "full",
            markerfacecoloralt="white",
            mew=1.6,
            mec=edges.get(s.get("variant", ""), colour),  # a labelled run's agent: edged, a colour per label
            label=label,
        )
    for (pred, _), points in curves.items():
        _, xs, ys = zip(*sorted(points), strict=True)
        ax.plot(xs, ys, ls=PREDICTOR_STYLE.get(family(pred), ":"), color=COLOURS["smpc"], lw=1, alpha=0.7)
    # budgets on the same point share one label; labels of points in order of goal rate alternate
    # above and below, so that two points close together do not write over each other
    for i, ((x, y), budgets) in enumerate(sorted(tags.items(), key=lambda item: item[0][::-1])):
        text = "B=" + ", ".join(f"{b:g}" for b in sorted(set(budgets)))
        ax.annotate(text, (x, y), textcoords="offset points", xytext=(6, 4 if i % 2 else -11), fontsize=8)
    handles, labels = ax.get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    ax.legend(unique.values(), unique.keys(), fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_xlabel("collision rate [%] (Wilson 95 % interval)")
    ax.set_ylabel("goal rate [%] (Wilson 95 % interval)")
    ax.set_xlim(left=-2)
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def verdicts(summary: list[dict[str, Any]]) -> str:
    """Markdown lines: which agents beat the IDM on both axes (none without an IDM row)."""
    idm = next((s for s in summary if s["agent"] == "idm"), None)
    if idm is None:
        return ""
    lines = [
        "",
        "Beats the IDM on both axes (a goal rate at least the IDM's, fewer collisions; point estimates):",
        "",
    ]
    for s in summary:
        if s is not idm:
            lines.append(f"- `{who(s)}`: {'yes' if beats(s, idm) else 'no'}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    parser = build_parser()
    args = parse_args(argv, parser)
    out = cli.open_output(parser, args, "frontier", FILES, argv)
    with out:
        summary, rows, wall = run(args, out)
        write_csvs(out.dir, "frontier", summary, rows)
        tables = markdown(summary, args, wall, out.command_line.strip()) + verdicts(summary)
        world = (args.env, args.duration, args.spawn_probability, args.seed, args.episodes)
        text = publish(out.dir, "frontier", tables, summary, title(*world))
    print(text)
    return summary


def title(env: str, duration: float, spawn: float, seed: int, episodes: int, note: str = "") -> str:
    """The figure's title: the episodes every point was measured on (``note``: appended)."""
    seeds = f"seeds {int(seed)}..{int(seed + episodes - 1)} (N = {int(episodes)} each{note})"
    return f"{env}, {duration:g} s, spawn {spawn:g}, {seeds}"


def publish(
    folder: Path, name: str, tables: str, summary: list[dict[str, Any]], heading: str, notes: str = ""
) -> str:
    """Write ``NAME.md`` (``tables`` as a section a docs page can include, the figure, then ``notes``)
    and draw ``NAME.png`` (:func:`draw_frontier`, titled ``heading``) in ``folder``; the Markdown."""
    text = f"<!-- --8<-- [start:tables] -->\n{tables}<!-- --8<-- [end:tables] -->\n"
    text += f"\n![frontier]({name}.png)\n" + (f"\n{notes}" if notes else "")
    (folder / f"{name}.md").write_text(text)
    draw_frontier(summary, folder / f"{name}.png", heading)
    return text


if __name__ == "__main__":
    main()
