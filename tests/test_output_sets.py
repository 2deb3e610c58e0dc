"""Results never lost or mixed (benchmarks.output): each run writes its whole output set with a
manifest, removes what an earlier run of the set wrote and it did not, replaces another
configuration only with --overwrite, and an interrupted sweep resumes to the same results."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from benchmarks import output, sampled, table2
from benchmarks.output import OutputError, OutputSet
from benchmarks.sweep import run_sweep

PPO_TABLE2 = ["--agents", "ppo:penalty", "--uncertainty", "low", "--workers", "1"]
"""The cheapest Table II run: one shipped policy, one level."""


def _set(out: Path, overwrite: bool = False, **options) -> OutputSet:
    options = {"out": out, "k": 1, "overwrite": overwrite, **options}
    return OutputSet(
        "demo", out, "demo", ("demo.csv", "demo_*.png"), options, ["--k", "1"], overwrite=overwrite
    )


def test_a_run_writes_its_set_with_a_manifest_and_removes_what_it_did_not_write(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "other_command.csv").write_text("not ours")
    with _set(out, overwrite=True) as run:  # demo files without a manifest need --overwrite once
        (run.dir / "demo.csv").write_text("a")
        (run.dir / "demo_1.png").write_text("b")
        assert not (out / "demo.csv").exists()  # nothing moves before the run is done
    manifest = json.loads((out / "demo.manifest.json").read_text())
    assert manifest["command"] == "python -m benchmarks.demo --k 1"
    assert set(manifest["files"]) == {"demo.csv", "demo_1.png"}
    assert manifest["configuration"] == {"k": 1} and manifest["version"]
    assert manifest["started"] <= manifest["finished"]
    with _set(out) as run:  # the same configuration: replaced without a flag
        (run.dir / "demo.csv").write_text("c")
    assert (out / "demo.csv").read_text() == "c" and not (out / "demo_1.png").exists()
    assert (out / "other_command.csv").read_text() == "not ours"
    assert sorted(p.name for p in out.iterdir()) == ["demo.csv", "demo.manifest.json", "other_command.csv"]


def test_results_older_than_manifests_can_be_adopted_by_their_command(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "demo.csv").write_text("computed before manifests")
    with pytest.raises(OutputError, match="without a manifest"):
        _set(out).check()
    manifest = _set(out).adopt("computed earlier by this command")
    assert manifest["adopted"] and list(manifest["files"]) == ["demo.csv"]
    _set(out).check()  # the same configuration now reruns without a flag
    with pytest.raises(OutputError, match="another configuration"):
        _set(out, k=2).check()


def test_another_configuration_needs_overwrite_and_a_failed_run_changes_nothing(tmp_path):
    out = tmp_path / "out"
    with _set(out) as run:
        (run.dir / "demo.csv").write_text("k=1")
    with pytest.raises(OutputError, match="another configuration \\(--k 1 there, 2 now\\).*--overwrite"):
        _set(out, k=2).check()
    with pytest.raises(RuntimeError), _set(out, k=2, overwrite=True) as run:
        (run.dir / "demo.csv").write_text("half")
        raise RuntimeError("interrupted")
    assert (out / "demo.csv").read_text() == "k=1"  # the earlier set, whole
    with pytest.raises(OutputError, match="--out .* is a file"):
        _set(out / "demo.csv" / "sub").check()


def test_table2_keeps_one_set_per_folder(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "t2"
    out.mkdir()
    (out / "fig3_trajectories.png").write_bytes(b"an older run's figure")
    (out / "sampled.csv").write_text("another command's file")
    with pytest.raises(SystemExit):  # files of an older version, without a manifest
        table2.main([*PPO_TABLE2, "--tolerances", "0", "--no-figures", "--out", str(out)])
    assert "without a manifest" in capsys.readouterr().err
    table2.main([*PPO_TABLE2, "--tolerances", "0", "--no-figures", "--out", str(out), "--overwrite"])
    assert not (out / "fig3_trajectories.png").exists()  # --no-figures: the old figure goes
    assert (out / "sampled.csv").exists()
    table2.main([*PPO_TABLE2, "--tolerances", "0", "--no-figures", "--out", str(out), "--workers", "2"])
    with pytest.raises(SystemExit):
        table2.main([*PPO_TABLE2, "--tolerances", "500", "--no-figures", "--out", str(out)])
    assert "--tolerances [0.0] there, [500.0] now" in capsys.readouterr().err
    manifest = json.loads((out / "table2.manifest.json").read_text())
    assert sorted(manifest["files"]) == ["table2.csv", "table2.md", "table2_meta.json", "table2_runs.npz"]
    names = {p.name for p in out.iterdir()}
    assert names == {*manifest["files"], "sampled.csv", "table2.manifest.json"}


class Interrupt(Exception):
    pass


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return [{k: v for k, v in r.items() if "ms" not in k} for r in csv.DictReader(f)]


def test_an_interrupted_sweep_resumes_to_the_results_of_an_uninterrupted_one(tmp_path, monkeypatch, capsys):
    pytest.importorskip("stable_baselines3")
    argv = ["--agents", "ppo:penalty", "--severities", "paper", "--tolerances", "0", "--uncertainty", "low"]
    argv += ["--episodes", "3", "--chunk", "1", "--workers", "1"]
    sampled.main([*argv, "--out", str(tmp_path / "clean")])
    run_job, calls, cut = sampled.run_job, [], [True]

    def interrupted(job):
        calls.append(job.seeds)
        if len(calls) == 2 and cut and cut.pop():
            raise Interrupt("power cut")
        return run_job(job)

    monkeypatch.setattr(sampled, "run_job", interrupted)
    out = tmp_path / "resumed"
    with pytest.raises(Interrupt):
        sampled.main([*argv, "--out", str(out)])
    assert [p.name for p in out.iterdir()] == [".sampled.partial"]  # no result yet, one chunk kept
    assert len(output.ChunkStore(out / ".sampled.partial" / "chunks")) == 1
    with pytest.raises(SystemExit):  # not silently restarted
        sampled.main([*argv, "--out", str(out)])
    assert "1 finished chunks of an interrupted run: pass --resume" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sampled.main([*argv, "--episodes", "4", "--out", str(out), "--resume"])
    assert "another configuration" in capsys.readouterr().err
    calls.clear()
    sampled.main([*argv, "--out", str(out), "--resume"])
    assert calls == [(1,), (2,)]  # the first chunk was not run again
    assert _rows(out / "sampled.csv") == _rows(tmp_path / "clean" / "sampled.csv")
    assert sorted(p.name for p in out.iterdir()) == ["sampled.csv", "sampled.manifest.json", "sampled.md"]


def _fail_on_three(x: int) -> int:
    if x == 3:
        raise Interrupt(x)
    return x * x


def test_the_sweep_keeps_each_finished_job_in_the_store(tmp_path):
    store = output.ChunkStore(tmp_path / "chunks")
    with pytest.raises(Interrupt):
        run_sweep(_fail_on_three, [1, 2, 3, 4], workers=1, store=store, desc="demo")
    assert len(store) == 2 and store.get("demo/1") == 4
    assert run_sweep(abs, [1, 2, -3, -4], workers=2, store=store, desc="demo") == [1, 4, 3, 4]


def _interrupt_second(module, name: str, monkeypatch) -> list:
    """Make ``module.name`` (a sweep's job function) raise on its second call, once."""
    job, calls, cut = getattr(module, name), [], [True]

    def interrupted(*args, **kwargs):
        calls.append(args[0])
        if len(calls) == 2 and cut and cut.pop():
            raise Interrupt("power cut")
        return job(*args, **kwargs)

    monkeypatch.setattr(module, name, interrupted)
    return calls


@pytest.mark.parametrize(
    ("command", "job", "argv", "table"),
    [
        ("stress", "run_job", ["--scenes", "2", "--agents", "rmpc", "--max-solve-time", "inf"], "stress.csv"),
        pytest.param(
            "highway_intersection",
            "run_chunk",
            ["--agents", "idm", "--episodes", "6", "--duration", "1"],
            "intersection_episodes.csv",
            marks=pytest.mark.slow,  # the same chunk store as stress and sampled, in a heavier env
        ),
    ],
)
def test_every_long_sweep_resumes_to_the_uninterrupted_results(
    tmp_path, monkeypatch, request, command, job, argv, table
):
    """``stress`` and ``highway_intersection`` (``heldout``, ``highway_frontier`` and ``prediction``
    share the same chunk store): interrupted after one chunk, ``--resume`` runs only the rest and
    writes the rows an uninterrupted run writes."""
    if command == "highway_intersection":
        pytest.importorskip("highway_env")
    if command == "stress":
        request.getfixturevalue("frozen_heap")  # it collects garbage before each episode
    module = __import__(f"benchmarks.{command}", fromlist=["main"])
    argv = [*argv, "--workers", "1"]
    module.main([*argv, "--out", str(tmp_path / "clean")])
    calls = _interrupt_second(module, job, monkeypatch)
    out = tmp_path / "resumed"
    with pytest.raises(Interrupt):
        module.main([*argv, "--out", str(out)])
    calls.clear()
    module.main([*argv, "--out", str(out), "--resume"])
    assert len(calls) == 1  # the first chunk was not run again
    assert _rows(out / table) == _rows(tmp_path / "clean" / table)


@pytest.mark.slow
def test_train_ppo_seeds_resume_to_the_uninterrupted_results(tmp_path, monkeypatch):
    """``train_ppo --seeds``: an interrupted run keeps its finished seeds; ``--resume`` trains only
    the others and ships the same seed with the same table."""
    pytest.importorskip("stable_baselines3")
    from benchmarks import ppo_eval, train_ppo

    argv = ["--total-timesteps", "384", "--n-steps", "128", "--num-envs", "3", "--seeds", "2"]
    argv += ["--eval-episodes", "1", "--no-progress-bar", "--name", "tiny"]
    train_ppo.main([*argv, "--out", str(tmp_path / "clean")])
    calls = _interrupt_second(ppo_eval, "evaluate", monkeypatch)
    out = tmp_path / "resumed"
    with pytest.raises(Interrupt):
        train_ppo.main([*argv, "--out", str(out)])
    calls.clear()
    train_ppo.main([*argv, "--out", str(out), "--resume"])
    assert len(calls) == 1  # seed 0 kept
    clean = json.loads((tmp_path / "clean" / "tiny_seeds.json").read_text())
    resumed = json.loads((out / "tiny_seeds.json").read_text())
    assert resumed["best"] == clean["best"] and resumed["results"] == clean["results"]


def test_the_manifests_commit_is_dirty_for_changed_code_not_for_the_runs_own_files(tmp_path, monkeypatch):
    import shutil
    import subprocess

    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    repo = tmp_path / "repo"
    (repo / "results" / "set").mkdir(parents=True)
    (repo / "code.py").write_text("x = 1\n")
    (repo / "results" / "set" / "table.csv").write_text("a\n1\n")

    def git(*args: str) -> None:
        subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True)

    git("init", "-q")
    git("-c", "user.name=t", "-c", "user.email=t@t", "add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "start")
    monkeypatch.setattr(output, "ROOT", repo)
    clean = output.git_commit()
    assert clean and not clean.endswith("+dirty")
    (repo / "results" / "set" / "table.csv").write_text("a\n2\n")  # a run replaced its own table
    assert output.git_commit() == clean + "+dirty"
    assert output.git_commit(repo / "results" / "set") == clean
    (repo / "code.py").write_text("x = 2\n")  # the code changed: dirty whatever the output
    assert output.git_commit(repo / "results" / "set") == clean + "+dirty"
