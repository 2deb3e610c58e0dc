"""The basic top view of ``RiskCrossing-v0`` with pygame (pygame-ce). The env chooses between it and
highway-env's graphics (:mod:`risk_env.highway.graphics`) in :mod:`risk_env.render.renderers`.

Drawn: the reference path (solid up to the goal, thin beyond it), the goal, each object's
predicted truncation boxes and means over the horizon (:func:`risk_env.predict` from its current
measurement, with its own uncertainty), the ego and object discs with their headings, an optional
planned ego trajectory and a status text. The view is fixed: it fits the path and every start
position.

``"rgb_array"`` needs no display (the SDL video driver defaults to ``dummy``); ``"human"`` opens a
window and needs a display.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np

from risk_env.models.path import point
from risk_env.prediction.belief import predict
from risk_env.scenario.scenario import Scenario

try:
    import pygame
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(
        "rendering RiskCrossing-v0 needs pygame (pygame-ce): pip install pygame-ce,"
        " or pip install 'riskcrossing[render]'"
    ) from exc

SIZE = (800, 450)
"""Frame size (width, height) [px]."""
MARGIN = 8.0
"""Free space [m] around the fitted scene."""
BEYOND_GOAL = 20.0
"""Length [m] of the path's continuation drawn beyond the goal."""

BACKGROUND = (246, 246, 242)
PATH = (110, 110, 110)
GOAL = (40, 150, 60)
EGO = (45, 95, 215)
OBJECT = (215, 60, 45)
BOX_NEAR = (235, 140, 30)
BOX_FAR = (250, 215, 170)
PLAN = (30, 170, 90)
TEXT = (30, 30, 30)


class Renderer:
    """Draws frames of one scenario. ``mode``: ``"rgb_array"`` (return frames) or ``"human"``."""

    def __init__(self, scenario: Scenario, mode: str, fps: float, size: tuple[int, int] = SIZE) -> None:
        if mode not in ("rgb_array", "human"):
            raise ValueError(f"unknown render mode {mode!r}; expected 'rgb_array' or 'human'")
        self.scenario = scenario
        self.mode = mode
        self.fps = fps
        self.size = size
        if mode == "rgb_array":
            os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
        pygame.font.init()
        self._font = pygame.font.Font(None, 20)
        self._surface = pygame.Surface(size)
        self._screen = None
        self._clock = None
        self._fit_view()
        lam = np.linspace(scenario.path.lambda_start, scenario.path.lambda_goal, 60)
        self._path_px = self._to_px(*point(scenario.path, lam)[:2])
        beyond = np.linspace(scenario.path.lambda_goal, scenario.path.lambda_goal + BEYOND_GOAL, 10)
        self._beyond_px = self._to_px(*point(scenario.path, beyond)[:2])

    def _fit_view(self) -> None:
        """Scale [px/m] and origin so that the path and both starts fit, aspect kept."""
        s = self.scenario
        lam = np.linspace(s.path.lambda_start, s.path.lambda_goal, 60)
        px, py, _ = point(s.path, lam)
        xs = np.concatenate([px, [s.ego.start.x], [o.start.x for o in s.objects]])
        ys = np.concatenate([py, [s.ego.start.y], [o.start.y for o in s.objects]])
        lo = np.array([xs.min(), ys.min()]) - MARGIN
        hi = np.array([xs.max(), ys.max()]) + MARGIN
        width, height = self.size
        self._scale = min(width / (hi[0] - lo[0]), height / (hi[1] - lo[1]))
        self._centre = 0.5 * (lo + hi)

    def _to_px(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """World [m] to pixel coordinates (y up on screen): ``(..., 2)``."""
        width, height = self.size
        u = width / 2 + (np.asarray(x) - self._centre[0]) * self._scale
        w = height / 2 - (np.asarray(y) - self._centre[1]) * self._scale
        return np.stack([u, w], axis=-1)

    def render(
        self,
        ego_pose: np.ndarray,
        ego_speed: float,
        object_measurements: np.ndarray,
        plan: np.ndarray | None = None,
        status: Sequence[str] = (),
    ) -> np.ndarray | None:
        """Draw one frame: ``ego_pose (3,)``, ``object_measurements (m, 5)`` = (c1, c2, theta, v,
        omega) of the scenario's first m objects (a single ``(5,)`` is the first), ``plan (M, 2)``
        [m] or None. Returns ``(H, W, 3)`` uint8 in ``"rgb_array"`` mode."""
        s = self.scenario
        measurements = np.atleast_2d(np.asarray(object_measurements, dtype=float))
        surf = self._surface
        surf.fill(BACKGROUND)
        pygame.draw.lines(surf, PATH, False, self._beyond_px.tolist(), 1)
        pygame.draw.lines(surf, PATH, False, self._path_px.tolist(), 3)
        goal = self._to_px(s.path.goal.x, s.path.goal.y)
        pygame.draw.circle(surf, GOAL, goal.tolist(), 5)

        # Each object's predicted truncation boxes and means, n = 1..N (near: dark).
        for measurement, u in zip(measurements, s.uncertainties, strict=False):
            beliefs = predict(s, measurement, uncertainty=u)[1:]
            for n, b in reversed(list(enumerate(beliefs, start=1))):
                colour = blend(BOX_NEAR, BOX_FAR, (n - 1) / max(len(beliefs) - 1, 1))
                corner = self._to_px(float(b.x) - float(b.half_x), float(b.y) + float(b.half_y))
                size = (2 * float(b.half_x) * self._scale, 2 * float(b.half_y) * self._scale)
                rect = pygame.Rect(*corner.tolist(), max(size[0], 1.0), max(size[1], 1.0))
                pygame.draw.rect(surf, colour, rect, 2)
                pygame.draw.circle(surf, colour, self._to_px(float(b.x), float(b.y)).tolist(), 3)

        if plan is not None and len(plan) > 0:
            pts = self._to_px(plan[:, 0], plan[:, 1]).tolist()
            if len(pts) > 1:
                pygame.draw.lines(surf, PLAN, False, pts, 2)
            for p in pts:
                pygame.draw.circle(surf, PLAN, p, 3)

        for (x, y, th, *_), obj in zip(measurements, s.objects, strict=False):
            self._disc(x, y, th, obj.radius, OBJECT)
        self._disc(ego_pose[0], ego_pose[1], ego_pose[2], s.ego.radius, EGO)
        for i, line in enumerate(status):
            surf.blit(self._font.render(line, True, TEXT), (8, 6 + 18 * i))

        if self.mode == "human":
            self._show()
            return None
        return frame_array(surf)

    def _disc(self, x: float, y: float, theta: float, radius: float, colour: tuple[int, int, int]) -> None:
        centre = self._to_px(x, y)
        r = max(radius * self._scale, 2.0)
        pygame.draw.circle(self._surface, colour, centre.tolist(), r)
        tip = centre + r * np.array([math.cos(theta), -math.sin(theta)])
        pygame.draw.line(self._surface, (255, 255, 255), centre.tolist(), tip.tolist(), 2)

    def _show(self) -> None:
        if self._screen is None:
            try:
                pygame.display.init()
                self._screen = pygame.display.set_mode(self.size)
            except pygame.error as exc:
                raise RuntimeError(
                    f"render_mode='human' needs a display ({exc}); use render_mode='rgb_array'"
                    " or set SDL_VIDEODRIVER=dummy"
                ) from exc
            pygame.display.set_caption("RiskCrossing-v0")
            self._clock = pygame.time.Clock()
        pygame.event.pump()
        self._screen.blit(self._surface, (0, 0))
        pygame.display.flip()
        self._clock.tick(self.fps)

    def close(self) -> None:
        """Close the window (``"human"``); frames of other renderers are unaffected."""
        if self._screen is not None:
            pygame.display.quit()
            self._screen = None


def frame_array(surface: pygame.Surface) -> np.ndarray:
    """The surface's pixels as ``(H, W, 3)`` uint8."""
    return np.ascontiguousarray(np.transpose(pygame.surfarray.array3d(surface), (1, 0, 2)))


def blend(a: tuple[int, int, int], b: tuple[int, int, int], t: float) -> tuple[int, int, int]:
    """The colour a fraction ``t`` of the way from ``a`` to ``b``."""
    return tuple(int(round((1 - t) * ca + t * cb)) for ca, cb in zip(a, b, strict=True))
