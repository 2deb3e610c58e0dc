"""The frontier of runs already made: drawn from their summaries, only on the same episodes."""

from __future__ import annotations

import csv
import hashlib
import json
import shutil
from pathlib import Path

import pytest

from benchmarks import highway_frontier_runs
from benchmarks.highway_frontier_runs import RunsError, gather

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results" / "highway"
RMPC, SMPC, IDM = "restart/40s_200", "restart/40s_200_smpc", "hardstop/40s_200_idm"


def copy_run(tmp_path: Path, name: str) -> Path:
    """A copy of the committed run ``name`` (its manifest and summary) to change."""
    folder = tmp_path / name.replace("/", "_")
    folder.mkdir()
    for file in ("intersection.manifest.json", "intersection.csv"):
        shutil.copy(RESULTS / name / file, folder / file)
    return folder


def edit_manifest(folder: Path, **options: object) -> None:
    path = folder / "intersection.manifest.json"
    manifest = json.loads(path.read_text())
    manifest["options"].update(options)
    path.write_text(json.dumps(manifest))


def edit_summary(folder: Path, recorded: bool = True, **values: object) -> None:
    """Change the summary's ``values``, as another run would have written it (``recorded``: with
    its manifest's SHA-256 of it), or behind its run's back."""
    path = folder / "intersection.csv"
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        row.update({k: str(v) for k, v in values.items()})
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    if recorded:
        manifest = json.loads((folder / "intersection.manifest.json").read_text())
        manifest["files"]["intersection.csv"]["sha256"] = hashlib.sha256(path.read_bytes()).hexdigest()
        (folder / "intersection.manifest.json").write_text(json.dumps(manifest))


def test_a_summary_changed_after_its_run_is_refused(tmp_path):
    run = copy_run(tmp_path, RMPC)
    edit_summary(run, recorded=False, goal_rate=0.99)
    with pytest.raises(RunsError, match="intersection.csv is not the file its run wrote"):
        gather([run])


def test_three_committed_runs_make_one_frontier(tmp_path, capsys):
    folders = [copy_run(tmp_path, name) for name in (RMPC, SMPC, IDM)]
    out = tmp_path / "out"
    rows = highway_frontier_runs.main(["--runs", *map(str, folders), "--out", str(out)])
    assert [r["agent"] for r in rows] == ["rmpc:worst_case", "smpc:exact:budget=0.05", "idm"]
    text = (out / "frontier_runs.md").read_text()
    with open(RESULTS / RMPC / "intersection.csv", newline="") as f:
        rmpc = next(csv.DictReader(f))
    goal = f"{100 * float(rmpc['goal_rate']):.1f}% [{100 * float(rmpc['goal_ci_low']):.1f}"
    assert goal in text  # the run's own figures, not recomputed
    assert "- `rmpc:worst_case (lane+interval)`: no" in text
    assert text.count("python -m benchmarks.highway_intersection") == 3  # each run's command
    assert text.index("[end:tables]") < text.index("The runs:")  # kept out of what a page includes
    assert (out / "frontier_runs.png").stat().st_size > 10_000
    assert (out / "frontier_runs.manifest.json").exists()
    with open(out / "frontier_runs.csv", newline="") as f:
        assert [r["run"] for r in csv.DictReader(f)] == list(map(str, folders))
    assert "seeds 0..199" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("option", "value"),
    [("duration", 13.0), ("seed", 5), ("episodes", 100), ("spawn_probability", 0.3), ("initial_vehicles", 3)],
)
def test_runs_of_other_episodes_are_refused_naming_the_setting(tmp_path, option, value):
    first, second = copy_run(tmp_path, RMPC), copy_run(tmp_path, IDM)
    edit_manifest(second, **{option: value})
    with pytest.raises(RunsError, match=f"{option} .* in {first}, {value!r} in {second}"):
        gather([first, second])


def test_a_run_without_duration_in_its_manifest_has_the_default(tmp_path):
    folder = copy_run(tmp_path, RMPC)
    manifest = json.loads((folder / "intersection.manifest.json").read_text())
    del manifest["options"]["duration"]
    (folder / "intersection.manifest.json").write_text(json.dumps(manifest))
    assert highway_frontier_runs.world(manifest)["duration"] == 13.0
    with pytest.raises(RunsError, match="duration 13.0"):
        gather([folder, copy_run(tmp_path, IDM)])


def test_an_agent_in_two_runs_is_drawn_once_if_its_outcomes_agree(tmp_path):
    first, twin = copy_run(tmp_path, IDM), tmp_path / "twin"
    shutil.copytree(first, twin)
    _, rows = gather([first, twin])
    assert len(rows) == 1 and rows[0]["run"] == str(first)
    edit_summary(twin, goal_rate=0.5)
    with pytest.raises(RunsError, match=f"idm .* differs in two runs: {first} and {twin}"):
        gather([first, twin])


def test_a_folder_without_a_run_or_named_twice_is_refused(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(RunsError, match="no run of highway_intersection"):
        gather([empty])
    run = copy_run(tmp_path, RMPC)
    with pytest.raises(RunsError, match="named twice"):
        gather([run, tmp_path / "." / run.name])
    (run / "intersection.csv").unlink()
    with pytest.raises(RunsError, match="intersection.csv is missing"):
        gather([run])


def test_bad_runs_fail_on_the_command_line_naming_runs_and_write_nothing(tmp_path, capsys):
    first, second = copy_run(tmp_path, RMPC), copy_run(tmp_path, IDM)
    edit_manifest(second, duration=13.0)
    out = tmp_path / "out"
    with pytest.raises(SystemExit):
        highway_frontier_runs.main(["--runs", str(first), str(second), "--out", str(out)])
    assert "--runs: the runs drove other episodes: duration" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(
    ("predictor", "expected"),
    [("lane", "lane"), ("lane+interval", "lane"), ("constant", "constant"), ("x", "x")],
)
def test_the_lane_predictors_variants_are_marked_as_the_lane_predictor(predictor, expected):
    from benchmarks.highway_frontier import family

    assert family(predictor) == expected


def test_runs_made_before_the_predictor_and_the_goals_interval_still_compose(tmp_path):
    old, new = RESULTS, RESULTS / "hindsight"  # the paper's predictor at 13 s; the hindsight reference
    manifests, rows = gather([old, new])
    assert [r["agent"] for r in rows] == [
        "rmpc:worst_case",
        "smpc:exact:probability:0.01",
        "idm",
        "hindsight",
    ]
    rmpc = rows[0]
    assert rmpc["predictor"] == "" and "goal_ci_low" not in next(iter(_summary(old)))
    assert rmpc["goal_ci_low"] < rmpc["goal_rate"] < rmpc["goal_ci_high"]  # its Wilson interval, made up
    assert highway_frontier_runs.world(manifests[0])["duration"] == 13.0  # None there: highway-env's 13 s
    text = highway_frontier_runs.markdown(manifests, rows, "the command")
    assert "| n/a |" in text  # deadlocks were not counted then


def _summary(folder: Path) -> list[dict[str, str]]:
    with open(folder / "intersection.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_a_label_draws_the_same_agent_of_two_runs_side_by_side(tmp_path, capsys):
    """Two runs of one agent with other options (here: other outcomes) are refused unlabelled, and
    drawn as two agents when one run is labelled (DIR=LABEL), the label in the table, the verdicts
    and the provenance."""
    first, second, idm = copy_run(tmp_path, RMPC), tmp_path / "second", copy_run(tmp_path, IDM)
    shutil.copytree(first, second)
    edit_summary(second, goal_rate=0.9, goal_ci_low=0.85, goal_ci_high=0.94)
    with pytest.raises(RunsError, match="a label, DIR=LABEL, tells them apart"):
        gather([first, second])
    _, rows = gather([first, (second, "passage"), idm])
    assert [(r["agent"], r["variant"]) for r in rows] == [
        ("rmpc:worst_case", ""),
        ("rmpc:worst_case", "passage"),
        ("idm", ""),
    ]
    out = tmp_path / "out"
    highway_frontier_runs.main(["--runs", str(first), f"{second}=passage", str(idm), "--out", str(out)])
    text = (out / "frontier_runs.md").read_text()
    assert "| rmpc:worst_case (lane+interval) [passage] |" in text
    assert "- `rmpc:worst_case (lane+interval) [passage]`: yes" in text  # 90 % goals, fewer collisions
    assert f"- `{second}` [passage] (run on" in text
    for bad, message in ((f"{second}=", "an empty label"), (f"{tmp_path / 'none'}=x", "not a folder")):
        with pytest.raises(SystemExit):
            highway_frontier_runs.main(["--runs", bad, "--out", str(tmp_path / "bad")])
        assert message in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()
