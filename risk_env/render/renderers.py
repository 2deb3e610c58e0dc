"""The env's choice of renderer: the one place that knows both the basic pygame view
(:mod:`risk_env.render.rendering`) and highway-env's (:mod:`risk_env.highway.graphics`); neither imports
this module, so the imports run one way."""

from __future__ import annotations

import importlib.util
from typing import Any

from risk_env.scenario.scenario import Scenario

RENDERERS: tuple[str, ...] = ("auto", "highway", "basic")


def make_renderer(kind: str, scenario: Scenario, mode: str, fps: float, estimator: str = "exact") -> Any:
    """The env's renderer: ``kind`` is ``"basic"`` (:class:`risk_env.render.rendering.Renderer`),
    ``"highway"`` (:class:`risk_env.highway.graphics.HighwayRenderer`, needs highway-env) or
    ``"auto"`` (highway when highway-env can be imported); ``mode`` ``"rgb_array"`` or ``"human"``;
    ``fps`` frames per second [1/s]; ``estimator`` names the env's risk estimator."""
    if kind == "auto":
        kind = "highway" if importlib.util.find_spec("highway_env") is not None else "basic"
    if kind == "highway":
        from risk_env.highway.graphics import HighwayRenderer  # an ImportError says how to install

        return HighwayRenderer(scenario, mode, fps, estimator=estimator)
    if kind == "basic":
        from risk_env.render.rendering import Renderer  # an ImportError says how to install pygame-ce

        return Renderer(scenario, mode, fps)
    raise ValueError(f"unknown renderer {kind!r}; expected one of {RENDERERS}")
