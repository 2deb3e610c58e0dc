"""What the benchmark commands show a person: their help, the main job's summary, the figures."""

from __future__ import annotations

import argparse
import csv
import importlib
import json
import re
from pathlib import Path

import numpy as np
import pytest

from benchmarks import figures, summary, table2, train_ppo
from benchmarks.__main__ import COMMANDS

ROOT = Path(__file__).resolve().parent.parent
COMMITTED = (ROOT / "docs" / "results", ROOT / "agents" / "models")


def load_rows(path: Path) -> list[dict]:
    """A Table II CSV as ``table2.run_one`` returns its rows."""
    rows = []
    with path.open() as f:
        for r in csv.DictReader(f):
            for key in ("epsilon", "e_acc", "d_min", "max_risk", "paper_e_acc", "paper_d_min"):
                r[key] = float(r[key])
            for key in ("solve_ms_median", "solve_ms_p95", "solve_ms_max", "wall_s"):
                r[key] = float(r[key])
            r["failed_solves"], r["steps"] = int(r["failed_solves"]), int(r["steps"])
            r["collided"], r["reached_goal"] = r["collided"] == "True", r["reached_goal"] == "True"
            rows.append(r)
    return rows


@pytest.mark.parametrize("name", COMMANDS)
def test_every_flag_has_help_and_shows_its_default(name):
    parser = importlib.import_module(f"benchmarks.{name}").build_parser()
    assert parser.prog == f"python -m benchmarks.{name}"
    text = parser.format_help()
    for marker in ("``", ":class:", ":mod:", ":func:", ":meth:", ":data:", "**"):
        assert marker not in text, f"raw reStructuredText {marker!r} in the help of {name}"
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
            continue  # help, and the hidden spellings of earlier versions
        assert action.help, f"{name} {action.option_strings} has no help"
        shown = parser.formatter_class(parser.prog)._get_help_string(action)
        assert "(default" in shown, f"{name} {action.option_strings} shows no default"


@pytest.mark.parametrize("name", COMMANDS)
def test_no_command_writes_into_the_committed_results_by_default(name):
    parser = importlib.import_module(f"benchmarks.{name}").build_parser()
    out = parser.get_default("out")
    if out is not None:
        resolved = Path(out).resolve()
        for committed in COMMITTED:
            assert committed.resolve() not in (resolved, *resolved.parents), f"{name} writes to {out}"


@pytest.mark.parametrize(
    ("asked", "n_steps", "num_envs", "trained"),
    [(4096, 128, 64, 8192), (8192, 128, 64, 8192), (8193, 128, 64, 16384), (100, 16, 4, 128)],
)
def test_train_ppo_rounds_up_to_whole_rollouts(asked, n_steps, num_envs, trained):
    args = train_ppo.parse_args(
        ["--total-timesteps", str(asked), "--n-steps", str(n_steps), "--num-envs", str(num_envs)]
    )
    assert train_ppo.planned_timesteps(args) == trained


def test_train_ppo_says_when_it_rounds(monkeypatch, capsys, tmp_path):
    monkeypatch.setattr(train_ppo, "train", lambda args, shown=None: {"asked": args.total_timesteps})
    out = ["--out", str(tmp_path)]
    assert train_ppo.main(["--total-timesteps", "4096", *out]) == {"asked": 4096}
    assert "--total-timesteps 4096 rounded up to 8192" in capsys.readouterr().out
    train_ppo.main(["--total-timesteps", "8192", "--overwrite", *out])
    assert "rounded" not in capsys.readouterr().out


def test_the_main_jobs_summary_fits_on_a_screen_and_explains_every_failure():
    """The committed full run: every claim that does not hold gets a why and a docs section; so do
    the grid RMPC's failed solves."""
    rows = load_rows(ROOT / "docs" / "results" / "table2.csv")
    meta = json.loads((ROOT / "docs" / "results" / "table2_meta.json").read_text())
    claims = table2.check_claims(rows)
    written = [Path("results") / n for n in ("table2.csv", "table2_runs.npz", "fig3_trajectories.png")]
    text = summary.summary(rows, claims, meta["wall_s"], Path("results/table2.md"), written)
    lines = text.splitlines()
    progress_bars = len(meta["wall_s"])  # one finished tqdm line per agent, on stderr
    assert len(lines) + progress_bars <= 40
    assert max(map(len, lines)) <= summary.WIDTH
    failed = [c for c, ok, _ in claims if ok is False]
    assert failed, "the committed run has claims that do not hold"
    listed = [re.match(r"^  (\d+)\. (holds|NO|not run) ", line) for line in lines]
    numbers = [int(m.group(1)) for m in listed if m]
    assert numbers == list(range(1, len(numbers) + 1)) and len(numbers) >= 5
    failing = [m for m in listed if m and m.group(2) == "NO"]
    holding = len(numbers) - len(failing)
    assert f"The paper's claims, {len(numbers)} as listed: {holding} hold, {len(failing)} do not." in text
    assert failing
    for i, line in enumerate(lines):
        if re.match(r"^  \d+\. NO ", line):
            why = " ".join(lines[i + 1 : i + 6])
            assert why.lstrip().startswith("why:") and "docs/reproduction.md#" in why
            assert "see docs" not in why, "a specific reason, not only a pointer"
    for column in ("e_acc: ", "d_min: ", "failed solver steps: "):  # each column defined on its line
        assert sum(line.startswith(column) for line in lines) == 1, column
    assert "e_acc/d_min" not in text and "failed solves" not in text
    grid = [r for r in rows if (r["method"], r["risk_method"]) == ("RMPC", "grid")]
    grid_failures = sum(r["failed_solves"] for r in grid)
    assert grid_failures > 0
    assert f"rmpc:grid: {grid_failures} failed solver steps" in text and summary.ANCHORS["grid"] in text
    assert "each the same in all" not in text  # the PPO rows vary: the policies see epsilon and the level
    ppo = [r for r in rows if r["method"] == "PPO"]
    assert len({(r["e_acc"], r["d_min"]) for r in ppo}) > 2
    assert "Written to results/: table2.md" in text


def test_the_summary_explains_collisions_beyond_the_tolerance():
    rows = load_rows(ROOT / "docs" / "results" / "plastic" / "table2.csv")
    text = summary.why(["No run collides"], rows)
    collided = [r for r in rows if r["collided"]]
    within = [r for r in collided if r["max_risk"] <= r["epsilon"] + 1e-6]
    assert f"{len(collided)} of {len(rows)} runs collided" in text
    assert f"{len(within)} of them within their tolerance" in text
    assert "plastic impact" in text


def test_claims_that_differ_in_their_variant_share_a_line():
    claims = [
        ("RMPC (grid) d_min grows with uncertainty", True, ""),
        ("RMPC (worst_case) d_min grows with uncertainty", True, ""),
        ("SMPC (exact) d_min falls as epsilon grows", False, ""),
        ("SMPC (monte_carlo) d_min falls as epsilon grows", True, ""),
        ("No run collides", False, ""),
    ]
    lines = [(text, ok) for text, ok, _ in summary.grouped(claims)]
    assert lines == [
        ("RMPC (grid, worst_case) d_min grows with uncertainty", True),
        ("SMPC (exact) d_min falls as epsilon grows", False),
        ("SMPC (monte_carlo) d_min falls as epsilon grows", True),
        ("No run collides", False),
    ]


def test_figures_label_coinciding_runs_and_draw_every_committed_run(tmp_path):
    same = np.zeros((5, 4))
    assert figures._twins([same, same + 1.0, same], ["low", "medium", "high"]) == ["", "", " (same as low)"]
    rows = load_rows(ROOT / "docs" / "results" / "table2.csv")
    arrays = dict(np.load(ROOT / "docs" / "results" / "table2_runs.npz"))
    written = figures.paper_figures(rows, arrays, tmp_path)
    names = ["fig3_trajectories.png", "fig4_velocities.png", "table2_at_a_glance.png"]
    assert [p.name for p in written] == names
    for path in written:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    ppo_only = [r for r in rows if r["method"] == "PPO"]
    assert figures.paper_figures(ppo_only, arrays, tmp_path / "none") == []
