"""What the env shows: the renderer it makes on first use and the planned trajectory drawn over
the scene (:class:`EnvView`); the env only says what to draw."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from risk_env.models.path import project
from risk_env.render.renderers import make_renderer
from risk_env.scenario.scenario import Scenario


class EnvView:
    """The renderer of one env (``kind`` of :data:`~risk_env.render.renderers.RENDERERS`,
    ``mode`` ``"rgb_array"`` or ``"human"``, ``fps`` [1/s], ``estimator`` the env's risk
    estimator's name), made on the first frame, and the plan overlay."""

    def __init__(self, kind: str, mode: str | None, fps: float, estimator: str) -> None:
        self.kind, self.mode, self.fps, self.estimator = kind, mode, fps, estimator
        self._renderer: Any = None
        self._plan: np.ndarray | None = None

    @property
    def plan(self) -> np.ndarray | None:
        """The planned ego positions ``(M, 2)`` [m] drawn over the scene, or None."""
        return None if self._plan is None else self._plan.copy()

    def set_plan(self, xy: Any) -> None:
        """Draw the positions ``xy (M, 2)`` [m] as the plan; None clears it."""
        if xy is None:
            self._plan = None
            return
        plan = np.array(xy, dtype=float)
        if plan.ndim != 2 or plan.shape[1] != 2 or plan.shape[0] < 1:
            raise ValueError(f"plan must have shape (M, 2) of positions [m], got {plan.shape}")
        if not np.all(np.isfinite(plan)):
            raise ValueError(f"plan has non-finite entries: {plan}")
        self._plan = plan

    def frame(
        self,
        scenario: Scenario,
        ego_pose: tuple[float, float, float],
        ego_speed: float,
        objects: Any,
        steps: int,
        risk: float,
    ) -> np.ndarray | None:
        """Draw ``scenario`` with the ego at ``ego_pose`` (c1 [m], c2 [m], theta [rad]) and speed
        [m/s], the objects' measurements ``(m, 5)``, after ``steps`` steps, the last of ``risk``:
        ``"rgb_array"`` returns the frame ``(H, W, 3)`` uint8, ``"human"`` draws to the window;
        without a render mode: a warning and None (as Gymnasium's envs do)."""
        if self.mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human' to"
                ' gym.make("RiskCrossing-v0", ...)'
            )
            return None
        lam = float(project(scenario.path, ego_pose[0], ego_pose[1]))
        status = (
            f"k = {steps}  t = {steps * scenario.dt:.1f} s",
            f"risk = {risk:.4g}  (eps = {scenario.risk_tolerance:g})",
            f"lambda = {lam:.1f} m",
        )
        if self._renderer is None:
            self._renderer = make_renderer(self.kind, scenario, self.mode, self.fps, self.estimator)
        return self._renderer.render(
            ego_pose=np.array(ego_pose),
            ego_speed=ego_speed,
            object_measurements=np.array(objects, dtype=float),
            plan=self._plan,
            status=status,
        )

    def close(self) -> None:
        """Close the renderer (a new one is made for the next frame)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
