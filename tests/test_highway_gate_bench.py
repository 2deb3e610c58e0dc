"""``python -m benchmarks.highway_gate``: the gate's verdicts against the future of a copy, on a
short episode, and its bad input."""

from __future__ import annotations

import copy
import csv

import numpy as np
import pytest

pytest.importorskip("highway_env")

from benchmarks import highway_gate  # noqa: E402


def test_a_short_run_judges_the_steps_at_the_line_and_tables_them(tmp_path, monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    out = tmp_path / "gate"
    argv = ["--episodes", "1", "--duration", "4", "--workers", "1", "--interval", "split_yield"]
    rows = highway_gate.main([*argv, "--given-ego", "--clearance", "2", "--out", str(out)])
    assert rows, "the ego reaches the line within 4 s on seed 0"
    assert all(r["seed"] == 0 and 0 <= r["step"] < 8 for r in rows)
    steps = [r["step"] for r in rows]
    assert steps == sorted(set(steps)) and steps == list(range(steps[0], steps[0] + len(steps)))
    for r in rows:  # a gate that closes gives how much time it missed by; one that opens, its slack
        assert r["open"] == (r["slack_s"] >= 0.5)
    with open(out / "gate.csv") as f:
        assert len(list(csv.DictReader(f))) == len(rows)
    text = (out / "gate.md").read_text()
    free, opened = sum(r["free"] for r in rows), sum(r["open"] for r in rows)
    assert f"| {len(rows)} | {free} (" in text and f"| {opened} (" in text
    assert "interval switches: split_yield" in text and "given that the ego goes" in text
    # the mean car with turn signals read, a chance tolerated: the same steps judged, the same futures
    loose = ["--signals", "--judge", "footprint", "--tolerance", "0.1", "--out", str(tmp_path / "loose")]
    looser = highway_gate.main([*argv, "--given-ego", "--clearance", "2", *loose])
    assert [r["step"] for r in looser] == steps and [r["free"] for r in looser] == [r["free"] for r in rows]
    text = (tmp_path / "loose" / "gate.md").read_text()
    assert "turn signals read" in text and "mean car" in text and "above a conflict chance of 0.1" in text


def test_a_lookahead_judges_going_at_once_over_its_own_time(tmp_path, monkeypatch):
    """Seed 5: the ego reaches the line at 4 s and, going at once, the goal before the episode's end
    (13 s, the env's) at both steps judged; over a lookahead of 1 s it cannot reach it."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    argv = ["--episodes", "1", "--seed", "5", "--duration", "5", "--workers", "1", "--given-ego"]
    whole = highway_gate.main([*argv, "--out", str(tmp_path / "whole")])
    short = highway_gate.main([*argv, "--lookahead", "1", "--out", str(tmp_path / "short")])
    assert [r["step"] for r in whole] == [r["step"] for r in short] and len(whole) == 2
    assert all(r["through"] and r["free"] for r in whole)
    assert not any(r["through"] for r in short)
    assert "| 2 | 2 (100.0% [" in (tmp_path / "whole" / "gate.md").read_text()
    text = (tmp_path / "short" / "gate.md").read_text()
    assert "going at once judged over 1 s" in text and "| 0 (of none) |" in text  # opened where through


def test_bad_input_is_named_before_any_episode(tmp_path, capsys):
    with pytest.raises(SystemExit):
        highway_gate.main(["--predictor", "lane", "--interval", "split_yield", "--out", str(tmp_path)])
    assert "--interval and --given-ego need --predictor lane+interval" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        highway_gate.main(["--interval", "bogus", "--out", str(tmp_path)])
    assert "unknown interval switch 'bogus'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        highway_gate.main(["--predictor", "constant", "--signals", "--out", str(tmp_path)])
    assert "--signals needs a lane predictor" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        highway_gate.main(["--lookahead", "-1", "--out", str(tmp_path)])
    assert "--lookahead" in capsys.readouterr().err


def test_the_rollout_judges_header_names_no_clearance_margin_or_tolerance(tmp_path, monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    argv = ["--episodes", "1", "--seed", "5", "--duration", "5", "--workers", "1", "--judge", "rollout"]
    rows = highway_gate.main([*argv, "--out", str(tmp_path)])
    assert len(rows) == 2 and all(r["slack_s"] in (float("inf"), -float("inf")) for r in rows)
    text = (tmp_path / "gate.md").read_text()
    assert "the scene rolled out with the ego going" in text
    assert "clearance" not in text and "margin" not in text and "conflict chance" not in text


def test_the_header_names_every_judge():
    from benchmarks.highway_gate import JUDGED
    from risk_env.highway.gate_judge import JUDGES

    assert set(JUDGED) == set(JUDGES) and len(set(JUDGED.values())) == len(JUDGES)


def test_the_ego_that_goes_at_once_may_drive_as_the_gate_assumes(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    from benchmarks.highway_hindsight import scheduled_vehicle
    from risk_env.highway import make_intersection_env
    from risk_env.highway.idm import put_ego

    env = make_intersection_env()
    env.reset(seed=0)
    speeds = {}
    for name, accel, cap in (("idm", None, None), ("planner", 3.0, 8.0)):
        sim = copy.deepcopy(env.unwrapped)
        put_ego(sim, scheduled_vehicle(sim, 0, "o1", accel, cap))
        sim.vehicle.speed = 0.0  # from a stop
        trace = []
        for _ in range(8):  # 4 s (the action is not read)
            sim.step(np.zeros(2, dtype=np.float32))
            trace.append(float(sim.vehicle.speed))
        speeds[name] = trace
    # the planners' ego accelerates at its 3 m/s^2 at most, not at the traffic's, up to its 8 m/s
    assert speeds["planner"][0] <= 3.0 * 0.5 + 1e-6 < speeds["idm"][0]
    assert max(speeds["planner"]) <= 8.0 + 1e-6
    assert set(highway_gate.FUTURE_EGOS) == {"idm", "planner"}
