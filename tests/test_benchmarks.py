"""Fast runs of the benchmark CLIs on tiny subsets (the full Table II is marked slow)."""

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks import sampled, table2
from benchmarks.sweep import run_sweep


def _square(x: int) -> int:
    return x * x


def test_table2_on_a_two_run_subset_writes_csv_md_and_figures(tmp_path):
    rows = table2.main(
        [
            "--agents",
            "rmpc:worst_case,smpc:exact",
            "--uncertainty",
            "low",
            "--tolerances",
            "0",
            "--out",
            str(tmp_path),
            "--workers",
            "1",
        ]
    )
    assert len(rows) == 2
    with (tmp_path / "table2.csv").open() as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames) == table2.CSV_COLUMNS
        written = list(reader)
    assert [r["method"] for r in written] == ["RMPC", "SMPC"]
    for r in written:
        assert float(r["d_min"]) > 3.0 and r["collided"] == "False"
        assert float(r["paper_e_acc"]) > 0 and math.isfinite(float(r["e_acc"]))
    md = (tmp_path / "table2.md").read_text()
    assert "The paper's claims" in md and "(53.5)" in md
    for png in ("fig3_trajectories.png", "fig4_velocities.png"):
        assert (tmp_path / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    runs = np.load(tmp_path / "table2_runs.npz")
    assert runs["RMPC/worst_case/low/eps=0/ego"].shape[1] == 4
    # exact SMPC at epsilon = 0 equals the RMPC (P = 0 is the box)
    assert rows[0]["d_min"] == pytest.approx(rows[1]["d_min"], abs=0.05)


def test_claims_checker_flags_what_fails():
    base = dict(method="RMPC", risk_method="worst_case", uncertainty="low", collided=False)
    rows = [
        {**base, "epsilon": 0.0, "e_acc": 50.0, "d_min": 9.0},
        {**base, "epsilon": 500.0, "e_acc": 60.0, "d_min": 9.0},
        {**base, "method": "SMPC", "risk_method": "exact", "epsilon": 0.0, "e_acc": 40.0, "d_min": 4.0},
        {
            **base,
            "method": "SMPC",
            "risk_method": "exact",
            "epsilon": 500.0,
            "e_acc": 41.0,
            "d_min": 5.0,
            "collided": True,
        },
    ]
    verdicts = {claim: ok for claim, ok, _ in table2.check_claims(rows)}
    assert verdicts["RMPC (worst_case) does not depend on epsilon"] is False
    assert verdicts["SMPC (exact) d_min falls as epsilon grows"] is False
    assert verdicts["No run collides"] is False
    assert verdicts["SMPC (exact) at or below RMPC (worst_case) in e_acc and d_min"] is True


def test_bad_cli_arguments_exit_with_a_message(capsys):
    for argv in (
        ["--agents", "mpc:exact"],
        ["--uncertainty", "extreme"],
        ["--tolerances", "a,b"],
        ["--tolerances", "-1"],
    ):
        with pytest.raises(SystemExit):
            table2.parse_args(argv)
    assert "unknown" in capsys.readouterr().err


def test_sampled_motion_study_on_two_episodes(tmp_path):
    rows = sampled.main(
        [
            "--agents",
            "smpc:exact",
            "--severities",
            "paper",
            "--uncertainty",
            "low",
            "--tolerances",
            "0",
            "--episodes",
            "2",
            "--out",
            str(tmp_path),
            "--workers",
            "1",
        ]
    )
    assert len(rows) == 1 and rows[0]["episodes"] == 2
    with (tmp_path / "sampled.csv").open() as f:
        assert tuple(csv.DictReader(f).fieldnames) == sampled.COLUMNS
    assert (
        0.0 <= rows[0]["collision_ci_low"] <= rows[0]["collision_rate"] <= rows[0]["collision_ci_high"] <= 1.0
    )


def test_wilson_interval():
    lo, hi = sampled.wilson(0, 200)
    assert lo == 0.0 and 0.015 < hi < 0.02
    lo, hi = sampled.wilson(100, 200)
    assert lo == pytest.approx(0.431, abs=1e-3) and hi == pytest.approx(0.569, abs=1e-3)


def test_process_pool_keeps_order():
    assert run_sweep(_square, list(range(7)), workers=2) == [x * x for x in range(7)]


@pytest.mark.slow  # starting ray costs more than the sweep; test_process_pool_keeps_order is the fast one
def test_ray_sweep_matches_the_process_pool():
    pytest.importorskip("ray")
    specs = table2.specs_for(["rmpc:worst_case"], ["low"], [0.0, 2500.0], {"max_steps": 6})
    local = run_sweep(table2.run_one, specs, workers=2)
    remote = run_sweep(table2.run_one, specs, ray_address="")
    for (row_a, arr_a), (row_b, arr_b) in zip(local, remote):
        assert {k: v for k, v in row_a.items() if "ms" not in k and k != "wall_s"} == {
            k: v for k, v in row_b.items() if "ms" not in k and k != "wall_s"
        }
        np.testing.assert_array_equal(arr_a["ego"], arr_b["ego"])


@pytest.mark.slow
def test_full_table2_reproduces_the_papers_trends(tmp_path):
    rows = table2.main(["--agents", "rmpc:worst_case,smpc:exact", "--out", str(tmp_path), "--no-figures"])
    verdicts = {claim: ok for claim, ok, _ in table2.check_claims(rows)}
    assert verdicts["RMPC (worst_case) does not depend on epsilon"]
    assert verdicts["RMPC (worst_case) d_min grows with uncertainty"]


COMMITTED = Path(__file__).resolve().parents[1] / "docs" / "results" / "table2.csv"
"""The committed Table II (one object, the paper's scene): every run must come out as it did."""
SAME_CELLS = (
    "e_acc",
    "d_min",
    "collided",
    "reached_goal",
    "steps",
    "failed_solves",
    "paper_e_acc",
    "paper_d_min",
)


def _committed() -> dict[tuple[str, str, str, float], dict[str, str]]:
    with COMMITTED.open() as f:
        return {
            (r["method"], r["risk_method"], r["uncertainty"], float(r["epsilon"])): r
            for r in csv.DictReader(f)
        }


def _assert_as_committed(row: dict, committed: dict[str, str]) -> None:
    """Cell by cell: the same numbers as written (CSV text), the largest risk to its 4 digits."""
    for column in SAME_CELLS:
        assert str(row[column]) == committed[column], (column, row[column], committed[column])
    assert row["max_risk"] == float(f"{float(committed['max_risk']):.4g}"), (row["max_risk"], committed)


FAST_CELLS = [
    ("rmpc:worst_case", "low", 0.0),
    ("rmpc:grid", "high", 2500.0),
    ("smpc:exact", "medium", 1500.0),
    ("smpc:exact", "high", 0.0),
    pytest.param("smpc:monte_carlo", "low", 500.0, marks=pytest.mark.slow),
    ("ppo:penalty", "medium", 1000.0),
]
"""A few Table II configurations, one per agent and level, for the default run. The Monte Carlo
SMPC's (its 500 draws make the costliest NLP of the table to build, as long as the rest of these
cells together) runs in the slow run, as every cell does in test_the_whole_table2_is_as_committed;
the default run checks the Monte Carlo SMPC's plans and their reproducibility in tests/test_agents.py
(test_monte_carlo_plan_respects_its_own_draws, test_monte_carlo_draws_are_reproducible)."""


@pytest.mark.parametrize(("agent", "level", "epsilon"), FAST_CELLS)
def test_table2_cells_are_as_committed(agent, level, epsilon):
    if agent.startswith("ppo"):
        pytest.importorskip("stable_baselines3")
    (spec,) = table2.specs_for([agent], [level], [epsilon], {})
    row, _ = table2.run_one(spec)
    _assert_as_committed(row, _committed()[(row["method"], row["risk_method"], level, epsilon)])


@pytest.mark.slow
def test_the_whole_table2_is_as_committed(tmp_path):
    pytest.importorskip("stable_baselines3")
    rows = table2.main(["--out", str(tmp_path), "--no-figures", "--workers", "2"])
    committed = _committed()
    assert len(rows) == len(committed) == 108
    for row in rows:
        _assert_as_committed(
            row, committed[(row["method"], row["risk_method"], row["uncertainty"], row["epsilon"])]
        )


def test_sampled_takes_tolerances_in_each_severitys_unit():
    parse = sampled.parse_tolerances
    assert parse(["0,1000"], ["paper", "plastic"]) == {"paper": [0.0, 1000.0], "plastic": [0.0, 1000.0]}
    got = parse(["0,2500", "probability=0,0.01", "injury=0.005"], ["paper", "probability", "injury"])
    assert got == {"paper": [0.0, 2500.0], "probability": [0.0, 0.01], "injury": [0.005]}  # not rescaled
    for groups, severities, message in (
        (
            ["0,1000"],
            ["paper", "probability"],
            "1000 exceeds 1, the largest per-step risk of the 'probability'",
        ),
        (["injury=3"], ["injury"], "3 exceeds 2, .* 'injury' severity \\[injuries\\]"),
        (["-1"], ["paper"], "-1.0 must be finite and >= 0 \\[J\\]"),
        (["nan"], ["plastic"], "nan must be finite"),
        (["a,b"], ["paper"], "expected numbers"),
        (["probability=0.1"], ["paper"], "names severity 'probability', not one of --severities"),
        (["injury=0.001"], ["injury", "paper"], "no tolerances for severity 'paper'"),
    ):
        with pytest.raises(ValueError, match=message):
            parse(groups, severities)


def test_sampled_cli_rejects_a_tolerance_in_another_unit(capsys):
    with pytest.raises(SystemExit):
        sampled.parse_args(["--severities", "probability", "--tolerances", "0,1000"])
    assert "exceeds 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sampled.parse_args(["--severities", "energy"])
    assert "unknown severity" in capsys.readouterr().err
    args = sampled.parse_args(["--severities", "injury", "--tolerances", "injury=0,0.005"])
    assert args.tolerances == {"injury": [0.0, 0.005]}


def test_sampled_rows_carry_the_unit_and_the_per_episode_columns(tmp_path):
    argv = ["--agents", "smpc:exact", "--severities", "injury", "--uncertainty", "high"]
    argv += ["--tolerances", "0.005", "--episodes", "2", "--out", str(tmp_path), "--workers", "1"]
    (row,) = sampled.main(argv)
    assert row["severity"] == "injury" and row["unit"] == "injuries" and row["epsilon"] == 0.005
    assert 0.0 < row["episode_risk_mean"] <= row["episode_risk_max"]
    assert row["risk_mean"] <= row["episode_risk_mean"]  # an episode has at least one step
    assert row["harm_per_episode"] >= 0.0
    assert "0.005 injuries" in (tmp_path / "sampled.md").read_text()


def test_table2_takes_the_injury_severity_in_its_unit(tmp_path, capsys):
    with pytest.raises(SystemExit):
        table2.parse_args(["--severity", "injury"])  # the paper's default tolerances are in J
    assert "500 exceeds 2" in capsys.readouterr().err
    argv = [
        "--agents",
        "smpc:exact",
        "--uncertainty",
        "low",
        "--severity",
        "injury",
        "--tolerances",
        "0.005",
    ]
    (row,) = table2.main(argv + ["--out", str(tmp_path), "--workers", "1", "--no-figures"])
    assert row["severity"] == "injury" and row["epsilon"] == 0.005 and not row["collided"]
    assert 0.0 <= row["max_risk"] <= 0.005 * (1 + 1e-6)
    assert math.isnan(row["paper_e_acc"])  # the paper's figures belong to its severity
    assert "injuries" in (tmp_path / "table2.md").read_text()


def test_table2_and_sampled_run_a_scene_with_several_objects(tmp_path):
    argv = ["--uncertainty", "low", "--tolerances", "0", "--scene", "two_crossing", "--workers", "1"]
    (row,) = table2.main(["--agents", "rmpc:worst_case", "--out", str(tmp_path / "t2"), *argv])
    assert not row["collided"] and row["failed_solves"] == 0  # one MPC against both objects
    assert math.isnan(row["paper_e_acc"])  # the paper's figures are for its own scene
    runs = np.load(tmp_path / "t2" / "table2_runs.npz")
    objects = runs["RMPC/worst_case/low/eps=0/objects"]
    assert (
        objects.shape == (row["steps"] + 1, 2, 4)
        and runs["RMPC/worst_case/low/eps=0/risk_terms"].shape[1] == 2
    )
    np.testing.assert_array_equal(objects[:, 0], runs["RMPC/worst_case/low/eps=0/object"])
    assert "Scene `two_crossing`" in (tmp_path / "t2" / "table2.md").read_text()
    assert (tmp_path / "t2" / "fig3_trajectories.png").read_bytes()[:4] == b"\x89PNG"
    argv = [
        "--agents",
        "smpc:exact",
        "--severities",
        "paper",
        "--episodes",
        "2",
        "--out",
        str(tmp_path / "s"),
    ]
    (row,) = sampled.main([*argv, "--uncertainty", "low", "--tolerances", "0", "--scene", "two_crossing"])
    assert row["scene"] == "two_crossing" and row["episodes"] == 2
    assert "Scene two_crossing" in (tmp_path / "s" / "sampled.md").read_text()
    with pytest.raises(SystemExit):
        table2.parse_args(["--scene", "three_crossing"])


def test_claims_say_lower_only_when_strictly_lower_and_name_ties():
    from benchmarks.claims import chain

    base = dict(uncertainty="low", collided=False)
    rows = [
        {**base, "method": "RMPC", "risk_method": "worst_case", "epsilon": 0.0, "e_acc": 50.0, "d_min": 8.0},
        {**base, "method": "SMPC", "risk_method": "exact", "epsilon": 0.0, "e_acc": 50.0, "d_min": 8.0},
        {
            **base,
            "method": "RMPC",
            "risk_method": "worst_case",
            "epsilon": 500.0,
            "e_acc": 50.0,
            "d_min": 8.0,
        },
        {**base, "method": "SMPC", "risk_method": "exact", "epsilon": 500.0, "e_acc": 40.0, "d_min": 3.0},
    ]
    claims = {claim: (ok, evidence) for claim, ok, evidence in table2.check_claims(rows)}
    ok, evidence = claims["SMPC (exact) at or below RMPC (worst_case) in e_acc and d_min"]
    assert ok and evidence == "e_acc lower in 1 of 2 runs, tied in 1; d_min lower in 1 of 2 runs, tied in 1"
    assert chain([8.11, 1.92, 1.92, 2.5]) == "8.11 > 1.92 = 1.92 < 2.50"
