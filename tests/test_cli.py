"""The benchmark commands' command lines: one agent grammar, checked values (every bad value an
error naming its flag, before any file is touched), help examples that run as printed."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import shlex
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchmarks import cli
from benchmarks.__main__ import COMMANDS
from benchmarks.__main__ import main as list_commands
from benchmarks.agent_names import AgentName, parse_agent, parse_agents

# ----------------------------------------------------------------------------------- the grammar


@pytest.mark.parametrize(
    ("text", "full"),
    [
        ("rmpc", "rmpc:worst_case"),
        ("rmpc:grid", "rmpc:grid"),
        ("smpc", "smpc:exact"),
        ("smpc:monte_carlo", "smpc:monte_carlo"),
        ("smpc:probability:0.01", "smpc:exact:probability:0.01"),
        ("smpc:monte_carlo:paper:1000", "smpc:monte_carlo:paper:1000"),
        ("smpc:budget=0.05", "smpc:exact:budget=0.05"),
        ("smpc:injury:0.001:budget=0.01", "smpc:exact:injury:0.001:budget=0.01"),
        ("ppo:lagrangian", "ppo:lagrangian"),
        ("idm", "idm"),
        ("hindsight", "hindsight"),
    ],
)
def test_every_agent_reads_back_from_its_full_name(text, full):
    agent = parse_agent(text)
    assert str(agent) == full and parse_agent(full) == agent


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("mpc", "unknown agent 'mpc': expected rmpc\\[:RISK\\], smpc"),
        ("rmpc:exact", "expected rmpc\\[:RISK\\], RISK one of worst_case, grid"),
        ("smpc:energy:5", "SEVERITY one of paper, plastic, probability, injury"),
        ("smpc:probability:2", "2 exceeds 1"),
        ("smpc:paper:abc", "the tolerance 'abc' is not a number"),
        ("smpc:budget=-1", "the budget -1.0 must be finite and >= 0"),
        ("rmpc:budget=1", "the RMPC has no risk budget"),
        ("ppo", "expected ppo:VARIANT"),
        ("idm:x", "idm takes no parts"),
        ("hindsight:5", "hindsight takes no parts"),
        ("smpc0", "'smpc0' is spelled 'smpc:paper:0' now"),
        ("smpc_exact", "'smpc_exact' is spelled 'smpc:exact' now"),
    ],
)
def test_a_bad_agent_name_says_what_is_valid(text, message):
    with pytest.raises(ValueError, match=message):
        parse_agent(text)


def test_commands_that_sweep_the_tolerance_take_agents_without_one():
    with pytest.raises(
        ValueError, match="sweeps the tolerance itself; name the agent without one, e.g. smpc:exact"
    ):
        parse_agent("smpc:paper:0", tolerance=False)
    with pytest.raises(ValueError, match="unknown agent 'idm': expected rmpc"):
        parse_agent("idm", ("rmpc", "smpc"))
    assert parse_agent("smpc").with_defaults("probability", 0.01) == AgentName(
        "smpc", "exact", "probability", 0.01
    )
    for text in ("", ",", "rmpc,,smpc", "rmpc,rmpc:worst_case"):
        with pytest.raises(ValueError):
            parse_agents(text)


# ------------------------------------------------------------------------------ python -m benchmarks


def test_python_m_benchmarks_lists_every_command_in_one_line_each(capsys):
    text = list_commands()
    folder = Path(__file__).resolve().parents[1] / "benchmarks"
    commands = sorted(
        p.stem for p in folder.glob("*.py") if "build_parser" in p.read_text() and p.stem != "cli"
    )
    assert sorted(COMMANDS) == commands
    for name in COMMANDS:
        (line,) = [line for line in text.splitlines() if line.split()[:1] == [name]]
        assert len(line) <= 110
    assert max(map(len, text.splitlines())) <= 110


def _parser(name: str) -> argparse.ArgumentParser:
    return importlib.import_module(f"benchmarks.{name}").build_parser()


@pytest.mark.parametrize("name", COMMANDS)
def test_every_command_has_a_working_help_without_abbreviations(name):
    parser = _parser(name)
    assert parser.allow_abbrev is False
    text = parser.format_help()
    commands = [line.split("#")[0].strip() for line in text.splitlines() if "python -m" in line]
    assert not any("  " in command for command in commands), "runs of spaces in an example"
    assert not any(line.rstrip().endswith("\\") for line in text.splitlines()), "a dangling backslash"
    for action in parser._actions:
        if action.help and action.help != argparse.SUPPRESS:
            shown = parser.formatter_class(parser.prog)._get_help_string(action)
            assert shown.count("default") <= 1 or "(default" not in action.help, (name, action.dest)


def test_abbreviated_flags_are_errors(capsys):
    from benchmarks import table2

    with pytest.raises(SystemExit):
        table2.parse_args(["--agent", "rmpc:worst_case"])  # --agents, abbreviated
    assert "unrecognized arguments: --agent" in capsys.readouterr().err


def test_old_flag_and_list_spellings_name_the_new_ones(capsys):
    from benchmarks import table2, vector_speed

    args = table2.parse_args(["--methods", "rmpc:worst_case", "--uncertainty", "low"])
    assert args.agents == ["rmpc:worst_case"]
    assert "--methods is deprecated, use --agents" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        vector_speed.main(["--num-envs", "1", "8", "64"])
    assert "takes a comma list now: --num-envs 1,8,64" in capsys.readouterr().err


# ------------------------------------------------------------------------------- the help examples


def examples() -> list[tuple[str, str]]:
    return [
        (name, line)
        for name in COMMANDS
        for line in cli.examples(importlib.import_module(f"benchmarks.{name}").__doc__)
    ]


SMALLEST = {
    "table2": {"--uncertainty": "low", "--tolerances": "0", "--workers": "1"},
    "sampled": {"--episodes": "1", "--chunk": "1", "--workers": "1"},
    "stress": {"--scenes": "1", "--workers": "1"},
    "heldout": {"--scenes": "1", "--workers": "1"},
    "timing": {"--steps": "1", "--uncertainty": "low", "--tolerances": "0"},
    "env_speed": {"--steps": "1", "--repeat": "1", "--batch": "1"},
    "vector_speed": {"--steps": "1", "--repeats": "1", "--num-envs": "1"},
    "exact_accuracy": {"--beliefs": "20"},
    "highway_intersection": {"--episodes": "1", "--workers": "1"},
    "highway_frontier": {"--episodes": "1", "--workers": "1"},
    "highway_frontier_runs": {},
    "highway_gate": {"--episodes": "1", "--duration": "1", "--workers": "1"},
    "highway_render": {"--max-steps": "2"},
    "prediction": {"--episodes": "1", "--duration": "1", "--workers": "1"},
    "train_ppo": {
        "--total-timesteps": "64",
        "--num-envs": "3",
        "--n-steps": "32",
        "--batch-size": "32",
        "--eval-episodes": "1",
        "--seeds": "1",
        "--checkpoint-every": "0",
    },
    "ppo_study": {"--total-timesteps": "64", "--episodes": "1"},
    "rollout": {},
}
"""The smallest episode count (and work) of each command, set on every example."""


def test_every_command_has_its_smallest_work():
    """The slow example runs need each command's entry in :data:`SMALLEST`: checked in the default run."""
    assert set(SMALLEST) == set(COMMANDS)


FAST = {
    "python -m benchmarks.env_speed --repeat 10 --out docs/results",
    "python -m benchmarks.vector_speed --num-envs 1,8,64 --modes vector_entry_point,sync,async",
    "python -m benchmarks.rollout --agent smpc:exact --uncertainty medium --tolerance 1000",
    "python -m benchmarks.highway_frontier_runs --runs docs/results/highway/restart/40s_200"
    " docs/results/highway/restart/40s_200_smpc docs/results/highway/hardstop/40s_200_idm"
    " --out results/highway/frontier_runs",
}
"""The examples the default test run runs (the others are marked slow). Two more run in it as other
tests: ``table2 --agents rmpc:worst_case,smpc:exact --uncertainty low`` at its smallest here is
``test_table2_on_a_two_run_subset_writes_csv_md_and_figures`` (tests/test_benchmarks.py), and
``stress --scenes 20 --agents rmpc`` is ``test_stress_benchmark_on_a_few_scenes`` (tests/test_stress.py)
with one agent fewer (it runs rmpc and smpc on 3 scenes)."""


def smallest(name: str, line: str, out: Path) -> list[str]:
    """The example ``line`` as arguments, with the smallest episode count and ``--out`` in ``out``."""
    argv = shlex.split(line.split("#")[0])[3:]
    changes = dict(SMALLEST[name])
    if "--out" in argv or _parser(name).get_default("out") is not None:  # never into the repository
        given = argv[argv.index("--out") + 1] if "--out" in argv else "out"
        changes["--out"] = str(out / Path(given).name) if name == "timing" else str(out / "out")
    for flag, value in changes.items():
        if flag in argv:
            argv[argv.index(flag) + 1] = value
        else:
            argv += [flag, value]
    return argv


def test_every_example_parses_and_fast_ones_are_marked():
    found = examples()
    assert len(found) >= 20
    for name, line in found:
        assert line.startswith(f"python -m benchmarks.{name}")
        argv = shlex.split(line.split("#")[0])[3:]
        _parser(name).parse_args(argv)  # every flag and value as printed is valid
    assert FAST <= {line.split("#")[0].strip() for _, line in found}


@pytest.mark.parametrize(
    ("name", "line"),
    [
        pytest.param(
            name, line, marks=() if line.split("#")[0].strip() in FAST else pytest.mark.slow, id=line[20:70]
        )
        for name, line in examples()
    ],
)
def test_a_help_example_runs_as_printed(name, line, tmp_path, capsys, request):
    if name in ("train_ppo", "ppo_study") or "ppo" in line:
        pytest.importorskip("stable_baselines3")
    if name == "stress":
        request.getfixturevalue("frozen_heap")  # it collects garbage before each episode
    importlib.import_module(f"benchmarks.{name}").main(smallest(name, line, tmp_path))
    assert capsys.readouterr().out.strip()


# -------------------------------------------------------------------------------- bad values


def _flags(name: str) -> list[argparse.Action]:
    return [
        a
        for a in _parser(name)._actions
        if a.option_strings and a.help != argparse.SUPPRESS and a.nargs != 0 and a.dest not in ("out", "ray")
    ]


NUMBERS = {
    "positive_int": ["0", "-1", "1.5", "x", ""],
    "nonnegative_int": ["-1", "-7", "0.5", "x", ""],
    "positive_float": ["0", "-0.5", "nan", "inf", "x", ""],
    "nonnegative_float": ["-1", "-1e-9", "nan", "inf", "-inf", "x"],
    "finite_float": ["nan", "inf", "-inf", "x", ""],
    "unit_interval_closed": ["-0.1", "1.5", "nan", "x"],
    "unit_interval": ["-0.1", "1", "1.5", "nan", "x"],
    "discount": ["0", "2", "-1", "nan", "x"],
    "fraction": ["0", "1.5", "-0.5", "nan", "x"],
    "time_cap": ["0", "-1", "nan", "x", ""],
    "positive_or_inf": ["0", "-1", "nan", "-inf", "x", ""],
}
"""Bad values of each checked ``type=`` of :mod:`benchmarks.cli`."""
LISTS = ["", ",", " , ", "a,,b", "@@@", "-1"]
"""Bad comma lists (of agents, names or numbers)."""
TEXT = {
    "name": ["", "../../escape", "a/b", ".hidden"],
    "uncertainty": ["", "extreme"],
    "tolerances": ["", "-5", "x"],
    "interval": ["bogus", "split_yield,bogus"],
    "runs": ["", "no/such/folder"],
}
"""Bad values of the plain-text flags (train_ppo's --name, --uncertainty, --tolerances; the
highway benchmarks' --interval; highway_frontier_runs' --runs)."""


def bad_values(action: argparse.Action) -> list[str]:
    kind = getattr(action.type, "__qualname__", "")
    if kind in NUMBERS:
        return NUMBERS[kind]
    if ".<locals>." in kind:  # a comma list
        return LISTS
    if action.choices is not None:
        return ["", "nonsense"]
    if action.dest in TEXT:
        return TEXT[action.dest]
    if action.dest in ("tolerances", "budgets"):  # sampled: [SEVERITY=]EPS,...
        return ["", "x", "-1", "energy=1"]
    if action.dest == "agents":  # stress: agent names, or the cap family's groups
        return LISTS
    if action.dest == "agent":  # rollout
        return ["", "x", "smpc0"]
    return []


def test_every_flag_has_bad_values():
    for name in COMMANDS:
        for action in _flags(name):
            assert bad_values(action), f"{name} {action.option_strings[0]}: no bad values to try"


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(folder)): p.read_bytes() if p.is_file() else b"" for p in sorted(folder.rglob("*"))
    }


def _fails(name: str, argv: list[str], flag: str) -> None:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        with pytest.raises(SystemExit) as stop:
            importlib.import_module(f"benchmarks.{name}").main(argv)
    assert stop.value.code not in (0, None), argv
    assert flag in err.getvalue(), (argv, err.getvalue())


CASES = [
    (name, action.option_strings[0], value)
    for name in COMMANDS
    for action in _flags(name)
    for value in bad_values(action)
]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=st.sampled_from(CASES))
def test_a_bad_value_of_any_flag_fails_naming_it_and_touches_no_file(case, tmp_path):
    name, flag, value = case
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    (out / "kept.txt").write_text("an earlier run's file")
    before = _snapshot(tmp_path)
    argv = [flag, value]
    if any(a.dest == "out" for a in _parser(name)._actions):
        argv += ["--out", str(out / "report.txt") if name == "timing" else str(out)]
    _fails(name, argv, flag)
    assert _snapshot(tmp_path) == before


@pytest.mark.parametrize(
    ("name", "argv", "flag"),
    [
        ("train_ppo", ["--eval-episodes", "-1", "--seeds", "2"], "--eval-episodes"),
        ("ppo_study", ["--episodes", "-1"], "--episodes"),
        ("train_ppo", ["--name", "../../escape"], "--name"),
        ("train_ppo", ["--name", ""], "--name"),
        ("train_ppo", ["--tolerances", "-5"], "--tolerances"),
        ("train_ppo", ["--gamma", "2"], "--gamma"),
        ("train_ppo", ["--net-arch", "0"], "--net-arch"),
        ("train_ppo", ["--cost-limit", "nan"], "--cost-limit"),
        ("highway_render", ["--fps", "0"], "--fps"),
        ("highway_render", ["--seed", "-1"], "--seed"),
        ("sampled", ["--workers", "-1"], "--workers"),
        ("stress", ["--workers", "0"], "--workers"),
        ("stress", ["--agents", ""], "--agents"),  # once ran the default agents
        ("vector_speed", ["--max-wrapped", "-1"], "--max-wrapped"),
        ("table2", ["--agents", ""], "--agents"),
        ("table2", ["--methods", ""], "--methods"),
        ("highway_intersection", ["--agents", ""], "--agents"),
        ("table2", ["--method", "rmpc:worst_case"], "--method"),
    ],
)
def test_the_bad_inputs_of_the_issue_fail_naming_their_flag(name, argv, flag, tmp_path):
    out = tmp_path / "out"
    _fails(name, [*argv, "--out", str(out)] if name != "vector_speed" else argv, flag)
    assert not out.exists()


def test_out_is_checked_before_any_work(tmp_path):
    blocker = tmp_path / "some_file"
    blocker.write_text("")
    for name in ("stress", "sampled", "heldout", "table2", "highway_intersection", "env_speed"):
        _fails(name, ["--out", str(blocker / "sub")], "--out")
    _fails("timing", ["--out", str(blocker / "timing.txt")], "--out")
    assert blocker.read_text() == ""
