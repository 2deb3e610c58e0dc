"""The README as a newcomer meets it: short, two commands first, and every Python block runs alone."""

from __future__ import annotations

import re
from pathlib import Path

import doc_blocks  # tests/doc_blocks.py
import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
BLOCKS = doc_blocks.fenced_blocks(README)
PYTHON_BLOCKS = doc_blocks.readme_python_blocks()


def test_readme_is_under_12_kb():
    assert len(README.encode()) < 12_000, f"README.md is {len(README.encode())} bytes"


def test_readme_starts_with_the_two_commands_each_in_its_own_block():
    first, second = BLOCKS[0], BLOCKS[1]
    assert first[0] == second[0] == "bash"
    main_job, tests = first[1].strip(), second[1].strip()
    assert "\n" not in main_job and "\n" not in tests, "each command is one line"
    assert main_job.endswith("python -m benchmarks.table2")
    assert tests.endswith("python -m pytest -q")
    for command in (main_job, tests):
        assert command.startswith('pip install "torch==') and "download.pytorch.org/whl/cpu" in command
    assert 'pip install -e ".[rl]"' in main_job and 'pip install -e ".[dev]"' in tests
    # nothing but the title and the pitch before them
    assert README.index("```") > README.index("## Install and run")


def test_ci_runs_the_readmes_test_command_itself():
    """``.ci/run`` reads the test command from README.md (one line matches its pattern: the second
    block's) and installs nothing of its own, so CI runs what a newcomer runs."""
    script = (ROOT / ".ci" / "run").read_text()
    (pattern,) = re.findall(r"grep -E '([^']+)' README.md", script)
    assert [line for line in README.splitlines() if re.search(pattern, line)] == [BLOCKS[1][1].strip()]
    assert not [line for line in script.splitlines() if line.lstrip().startswith(("pip ", "python "))]


def test_readme_states_the_python_versions_and_the_cpu_index():
    assert "Python 3.10 to 3.13" in README
    assert "--index-url https://download.pytorch.org/whl/cpu" in README


def test_readme_has_quick_starts_for_the_mpc_ppo_and_highway_env():
    assert len(PYTHON_BLOCKS) == 3
    assert "SMPC" in PYTHON_BLOCKS[0] and "PPOAgent" in PYTHON_BLOCKS[1]
    assert "IntersectionAdapter" in PYTHON_BLOCKS[2]


def check_block_output(index: int, result: doc_blocks.Result) -> None:
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.strip(), "each block prints what it found"
    if index == 0:  # an episode's summary, not the last step's values
        for word in ("smallest distance", "largest risk", "goal", "collision"):
            assert word in result.stdout, word
    if index == 1:  # the PPO policy's return beside the MPC's, on the same episode
        lines = result.stdout.strip().splitlines()
        assert len(lines) == 2 and all("return" in line for line in lines)
        assert lines[0].startswith("PPO") and lines[1].startswith("SMPC")


@pytest.mark.parametrize("index", range(len(PYTHON_BLOCKS)))
def test_every_python_block_runs_alone(index, blocks_run_alone):
    """Each block in a namespace, a folder and a Gymnasium registry of its own, all in this
    interpreter (tests/doc_blocks.py); the ``slow`` test below gives each a fresh interpreter."""
    code = PYTHON_BLOCKS[index]
    if (module := doc_blocks.missing_extra(code)) is not None:
        pytest.skip(f"the block needs {module} (an optional extra)")
    check_block_output(index, blocks_run_alone[code])


@pytest.mark.slow  # one interpreter per block; test_every_python_block_runs_alone is the fast one
@pytest.mark.parametrize("index", range(len(PYTHON_BLOCKS)))
def test_every_python_block_runs_alone_in_a_fresh_interpreter(index, tmp_path):
    code = PYTHON_BLOCKS[index]
    if (module := doc_blocks.missing_extra(code)) is not None:
        pytest.skip(f"the block needs {module} (an optional extra)")
    check_block_output(index, doc_blocks.run_alone(code, tmp_path))


def test_readme_links_resolve():
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README):
        if not target.startswith(("http://", "https://")):
            assert (ROOT / target).exists(), f"README links to a missing {target}"


def test_readme_citation_is_the_docs_one():
    bib = (ROOT / "docs" / "citation.bib").read_text().strip()
    blocks = [code.strip() for lang, code in BLOCKS if lang == "bibtex"]
    assert blocks == [bib]
    assert "2304.12063" in bib and "Tolksdorf, Leon and Tejada, Arturo and van de Wouw, Nathan" in bib
