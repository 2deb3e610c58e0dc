"""Shared fixtures, and the test process's settings: rendering runs headless (SDL's video driver
defaults to ``dummy``), solver calls past their iteration limit raise, and what keeps the default run
within its CPU budget (Hypothesis imported without assertion rewriting, every built solver kept,
fewer full garbage collections; see README.md for the run's time)."""

from __future__ import annotations

import gc
import importlib
import os
import sys

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
# a solver call past its rung's iteration limit raises (agents.mpc.nlp.calls), here and in worker processes
os.environ.setdefault("RISKCROSSING_STRICT_ITERATIONS", "1")


def _import_without_assertion_rewriting(*names: str) -> None:
    """Import ``names`` with pytest's assertion rewriting set aside. pytest rewrites the asserts of
    every module of a package that ships a pytest plugin, as Hypothesis does: some 70 modules whose
    asserts are Hypothesis's own, rewritten on every run (about 2 s of CPU). The tests' own modules
    are rewritten as ever."""
    hooks = [h for h in sys.meta_path if type(h).__module__ == "_pytest.assertion.rewrite"]
    for hook in hooks:
        sys.meta_path.remove(hook)
    try:
        for name in names:
            importlib.import_module(name)
    finally:
        sys.meta_path[:0] = hooks


_import_without_assertion_rewriting("hypothesis", "hypothesis.strategies")

import doc_blocks  # noqa: E402  (tests/doc_blocks.py)
import pytest  # noqa: E402

from agents.mpc.nlp import solver  # noqa: E402
from risk_env.scenario.scenario import Scenario  # noqa: E402

# The suite builds some 220 different problems, many of them in several tests far apart: the test
# process keeps every one it built rather than the 48 a process keeps, so that each is built once.
solver._CACHE_SIZE = 1000
# ... and with them a large heap (every module the suite imports), which each full garbage
# collection walks: full collections a tenth as often as Python's default (every 100 collections of
# the middle generation, not 10). Nothing is kept that would be freed, only later.
gc.set_threshold(700, 10, 100)


@pytest.fixture
def short_scenario() -> Scenario:
    """The paper's low-uncertainty scenario with a short horizon and episode (fast tests)."""
    return Scenario.preset("low", horizon=3, max_steps=12)


@pytest.fixture(scope="session")
def blocks_run_alone() -> dict[str, doc_blocks.Result]:
    """Every Python block of README.md and docs/ (but those whose optional extra is missing), each
    run as if alone in this interpreter (:func:`doc_blocks.run_each_alone`): code -> result."""
    codes = [*doc_blocks.readme_python_blocks(), *doc_blocks.docs_python_blocks().values()]
    codes = list(dict.fromkeys(c for c in codes if doc_blocks.missing_extra(c) is None))
    return dict(zip(codes, doc_blocks.run_each_alone(codes), strict=True))


@pytest.fixture
def frozen_heap():
    """The test's own objects only, for garbage collections the code asks for (``benchmarks.stress``
    collects before each episode): the test process holds every module the suite imported and every
    solver it built, which a full collection would walk each time (about 0.4 s). Nothing is lost:
    the frozen objects are collectable again after the test."""
    gc.freeze()
    yield
    gc.unfreeze()


def pytest_sessionfinish(session):
    """The run is over: pytest's last garbage collections (five of them, to report exceptions in
    finalizers) need not walk the whole heap of the test process again."""
    gc.freeze()


@pytest.fixture(scope="session")
def network():
    """``intersection-v2``'s road network (after a reset with seed 0); skips without highway-env."""
    pytest.importorskip("highway_env")
    from risk_env.highway import make_intersection_env

    env = make_intersection_env()
    env.reset(seed=0)
    return env.unwrapped.road.network
