"""The Python blocks of README.md and docs/, and how the tests run them alone.

:func:`run_alone` runs one block in a fresh interpreter (the slow tests, one process per block);
:func:`run_each_alone` runs blocks in this interpreter (the default run), each as if alone: in a
namespace of its own, from an empty folder of its own, its output captured, and with
RiskCrossing's Gymnasium id unregistered before it and registered again only when the block itself
imports the project (as a fresh interpreter registers it on ``import risk_env``, ``agents`` or
``benchmarks``), so a block that makes the env without that import fails here as it would alone.
The imports and the process-wide solver cache are shared, which is what makes it fast; the
registry is restored afterwards.
"""

from __future__ import annotations

import builtins
import contextlib
import importlib.util
import io
import os
import re
import subprocess
import sys
import tempfile
import traceback
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
FENCED = re.compile(r"^```(\w*)\n(.*?)^```", flags=re.DOTALL | re.MULTILINE)
OPTIONAL = {
    "agents.ppo.policy": "stable_baselines3",
    "PPOAgent": "stable_baselines3",
    "risk_env.highway": "highway_env",
}
"""What a block mentions -> the optional module it then needs (skipped when missing)."""


def fenced_blocks(text: str) -> list[tuple[str, str]]:
    """``(language, code)`` of every fenced block of a Markdown ``text``."""
    return FENCED.findall(text)


def doc_pages() -> list[Path]:
    """The docs site's pages (not the generated results)."""
    return sorted(p for p in DOCS.rglob("*.md") if "results" not in p.relative_to(DOCS).parts)


def readme_python_blocks() -> list[str]:
    return [code for lang, code in fenced_blocks((ROOT / "README.md").read_text()) if lang == "python"]


def docs_python_blocks() -> dict[str, str]:
    """``{"<page>-<i>": code}`` of every Python block of the docs' pages."""
    return {
        f"{page.stem}-{i}": code
        for page in doc_pages()
        for i, code in enumerate(c for lang, c in fenced_blocks(page.read_text()) if lang == "python")
    }


def missing_extra(code: str) -> str | None:
    """The optional module ``code`` needs and this environment lacks, if any."""
    for needle, module in OPTIONAL.items():
        if needle in code and importlib.util.find_spec(module) is None:
            return module
    return None


@dataclass(frozen=True)
class Result:
    returncode: int
    stdout: str
    stderr: str


def _environment() -> dict[str, str]:
    """Headless, this checkout importable."""
    return {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
        "SDL_VIDEODRIVER": "dummy",
        "MPLBACKEND": "Agg",
    }


def run_alone(code: str, cwd: Path, timeout: float = 120.0) -> Result:
    """``code`` in a fresh interpreter, in the folder ``cwd``, headless, this checkout importable."""
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=cwd,
        env=_environment(),
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    return Result(done.returncode, done.stdout, done.stderr)


def run_each_alone(codes: list[str]) -> list[Result]:
    """Each of ``codes`` as if alone (see the module's docstring), in this interpreter."""
    import gymnasium

    saved = dict(gymnasium.registry)
    try:
        return [_run_in_fresh_namespace(code) for code in codes]
    finally:
        gymnasium.registry.clear()
        gymnasium.registry.update(saved)


PACKAGES = ("risk_env", "agents", "benchmarks")
"""The project's packages: importing any of them imports ``risk_env``, which registers its env."""


def _registered() -> bool:
    import gymnasium

    return any(str(spec.entry_point).startswith("risk_env") for spec in gymnasium.registry.values())


def _forget_registrations() -> None:
    """Unregister RiskCrossing's Gymnasium ids (what a fresh interpreter starts without)."""
    import gymnasium

    for env_id, spec in list(gymnasium.registry.items()):
        if str(spec.entry_point).startswith("risk_env"):
            del gymnasium.registry[env_id]


def _importing(name: str, globals=None, locals=None, fromlist=(), level: int = 0):  # noqa: A002
    """``__import__`` that registers the env again when a block imports the project, as the
    first import of ``risk_env`` does in a fresh interpreter (``risk_env/__init__.py`` run again)."""
    module = builtins.__import__(name, globals, locals, fromlist, level)
    if level == 0 and name.partition(".")[0] in PACKAGES and not _registered():
        importlib.reload(sys.modules["risk_env"])
    return module


def _run_in_fresh_namespace(code: str) -> Result:
    out, err = io.StringIO(), io.StringIO()
    returncode = 0
    _forget_registrations()
    with tempfile.TemporaryDirectory(prefix="block_") as cwd:
        here = os.getcwd()
        os.chdir(cwd)
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                try:
                    namespace = {
                        "__name__": "__main__",
                        "__builtins__": {**vars(builtins), "__import__": _importing},
                    }
                    exec(compile(code, "<block>", "exec"), namespace)
                except SystemExit as stop:
                    returncode = stop.code if isinstance(stop.code, int) else int(stop.code is not None)
                except Exception:  # noqa: BLE001  (the block's failure is its result)
                    traceback.print_exc()
                    returncode = 1
        finally:
            os.chdir(here)
    return Result(returncode, out.getvalue(), err.getvalue())
