"""Shared fixtures. Rendering runs headless: SDL's video driver defaults to ``dummy``."""

from __future__ import annotations

import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
# a solver call past its rung's iteration limit raises (agents.mpc.nlp.calls), here and in worker processes
os.environ.setdefault("RISKCROSSING_STRICT_ITERATIONS", "1")

import pytest  # noqa: E402

from risk_env.scenario.scenario import Scenario  # noqa: E402


@pytest.fixture
def short_scenario() -> Scenario:
    """The paper's low-uncertainty scenario with a short horizon and episode (fast tests)."""
    return Scenario.preset("low", horizon=3, max_steps=12)
