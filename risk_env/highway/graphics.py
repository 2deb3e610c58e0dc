"""Drawing with highway-env's graphics: ``RiskCrossing-v0`` in highway-env's look, and our overlays
on any highway-env scene.

- :class:`HighwayRenderer`: the env's ``renderer="highway"`` (the default when highway-env is
  installed). The reference arc is a highway-env lane (a ``CircularLane`` fitted to the arc, or a
  ``StraightLane`` for curvature 0), each object's constant-input course another, the ego and the
  objects are highway-env vehicles, and on top: the collision discs, each object's truncation boxes
  and means over the horizon, their Monte Carlo draws when the env's estimator is ``"monte_carlo"``
  (from the renderer's own seeded generator, so rendering never changes the env's random stream),
  the plan set by ``env.set_plan``, the goal and a status text. Same view as the basic renderer,
  y up (highway-env draws y down: the scene is drawn in highway-env's way and flipped).
- :func:`render_scene`: a frame of a highway-env env (its road and traffic) with the same
  overlays, for the intersection adapter's frames.

Both draw on plain surfaces: no display is needed (``"human"`` opens a window).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from risk_env.highway.common import require_highway_env

require_highway_env()

import pygame  # noqa: E402  (pygame-ce, brought by highway-env)
from highway_env.road.graphics import RoadGraphics, WorldSurface  # noqa: E402
from highway_env.road.lane import AbstractLane, CircularLane, LineType, StraightLane  # noqa: E402
from highway_env.road.road import Road, RoadNetwork  # noqa: E402
from highway_env.vehicle.graphics import VehicleGraphics  # noqa: E402
from highway_env.vehicle.kinematics import Vehicle  # noqa: E402

from risk_env.models.path import point  # noqa: E402
from risk_env.prediction.belief import Belief, predict, predict_array  # noqa: E402
from risk_env.prediction.mixture import Mixture  # noqa: E402
from risk_env.render.rendering import BEYOND_GOAL, SIZE, Renderer, blend, frame_array  # noqa: E402
from risk_env.scenario.scenario import Scenario  # noqa: E402

EGO = VehicleGraphics.EGO_COLOR
OBJECT = VehicleGraphics.BLUE
CRASHED = VehicleGraphics.RED
BOX_NEAR = (255, 150, 30)
BOX_FAR = (255, 225, 160)
SAMPLE = (255, 90, 60)
PLAN = (120, 255, 120)
GOAL = (255, 255, 255)
ROUTE = (180, 230, 255)
DISC = (255, 255, 255)
TEXT = (20, 20, 20)
TEXT_BACKGROUND = (235, 235, 235)
MIN_OPACITY = 0.15
"""Smallest opacity of a drawn mode (its weight otherwise)."""
SAMPLE_SEED = 0
"""Seed of the renderer's generator for the Monte Carlo draws it shows."""


def arc_lane(
    x: float,
    y: float,
    theta: float,
    curvature: float,
    length: float,
    line_types: Sequence[int] = (LineType.CONTINUOUS, LineType.CONTINUOUS),
    width: float = AbstractLane.DEFAULT_WIDTH,
) -> AbstractLane:
    """A highway-env lane along the arc that starts at ``(x, y, theta)`` [m, m, rad] with
    ``curvature`` [1/m] (positive: heading increases) for ``length`` [m]: a ``CircularLane`` (its
    ``clockwise`` means heading-increasing) or, for curvature 0, a ``StraightLane``."""
    if abs(curvature) < 1e-9:
        start = np.array([x, y])
        end = start + length * np.array([math.cos(theta), math.sin(theta)])
        return StraightLane(start, end, width=width, line_types=list(line_types))
    radius = 1.0 / abs(curvature)
    centre = np.array([x, y]) + (1.0 / curvature) * np.array([-math.sin(theta), math.cos(theta)])
    side = 1.0 if curvature > 0 else -1.0  # the centre is left (+) or right (-) of the heading
    start_phase = theta - side * math.pi / 2
    end_phase = start_phase + curvature * length
    return CircularLane(
        centre,
        radius,
        start_phase,
        end_phase,
        clockwise=curvature > 0,
        width=width,
        line_types=list(line_types),
    )


def draw_polyline(
    surface: WorldSurface, xy: np.ndarray, colour: tuple[int, ...], width: int = 2, dots: bool = True
) -> None:
    """A line through world points ``xy (M, 2)`` [m], with a dot on each (``dots``)."""
    pts = [surface.vec2pix(p) for p in np.asarray(xy, dtype=float)]
    if len(pts) > 1:
        pygame.draw.lines(surface, colour, False, pts, width)
    for p in pts if dots else ():
        pygame.draw.circle(surface, colour, p, max(width + 1, 2))


def draw_beliefs(surface: WorldSurface, beliefs: Sequence[Belief]) -> None:
    r"""Truncation boxes and means of beliefs $n = 1, \dots, N$ (near: dark orange, far: pale)."""
    count = len(beliefs)
    for n, b in reversed(list(enumerate(beliefs))):
        colour = blend(BOX_NEAR, BOX_FAR, n / max(count - 1, 1))
        x, y, hx, hy = float(b.x), float(b.y), float(b.half_x), float(b.half_y)
        (u0, w0), (u1, w1) = surface.vec2pix((x - hx, y - hy)), surface.vec2pix((x + hx, y + hy))
        rect = pygame.Rect(min(u0, u1), min(w0, w1), max(abs(u1 - u0), 1), max(abs(w1 - w0), 1))
        pygame.draw.rect(surface, colour, rect, 2)
        pygame.draw.circle(surface, colour, surface.vec2pix((x, y)), 3)


def box_corners(x: float, y: float, half_x: float, half_y: float, frame: float) -> np.ndarray:
    """The corners ``(4, 2)`` [m] of the box ``+-half_x`` along the axis at angle ``frame`` [rad]
    and ``+-half_y`` across it, centred at ``(x, y)``."""
    c, s = math.cos(frame), math.sin(frame)
    local = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]]) * np.array([half_x, half_y])
    return np.array([x, y]) + local @ np.array([[c, s], [-s, c]])


def draw_mixtures(
    surface: WorldSurface, mixtures: Sequence[Mixture], min_opacity: float = MIN_OPACITY
) -> None:
    r"""Every mode of every mixture over $n = 1, \dots, N$: its truncation boxes in the mode's own frame
    (the belief's ``frame`` [rad], 0 when it has none: the world's axes) and its means joined,
    near dark orange to far pale, with the mode's weight as opacity (at least ``min_opacity``, so
    an unlikely mode stays visible). Drawn on a transparent layer blended onto ``surface``."""
    layer = pygame.Surface(surface.get_size(), pygame.SRCALPHA)
    for mixture in mixtures:
        for mode in sorted(mixture.modes, key=lambda m: m.weight):  # the likeliest on top
            alpha = round(255 * max(min_opacity, min(1.0, float(mode.weight))))
            b = mode.beliefs
            frames = np.broadcast_to(np.asarray(getattr(b, "frame", 0.0), dtype=float), np.shape(b.x))
            steps = len(np.atleast_1d(b.x)) - 1
            means = []
            for n in range(steps, 0, -1):
                colour = (*blend(BOX_NEAR, BOX_FAR, (n - 1) / max(steps - 1, 1)), alpha)
                x, y = float(b.x[n]), float(b.y[n])
                corners = box_corners(x, y, float(b.half_x[n]), float(b.half_y[n]), float(frames[n]))
                pygame.draw.polygon(layer, colour, [surface.vec2pix(p) for p in corners], 2)
                means.append(surface.vec2pix((x, y)))
            if len(means) > 1:
                pygame.draw.lines(layer, (*BOX_NEAR, alpha), False, means, 2)
    surface.blit(layer, (0, 0))


def draw_samples(surface: WorldSurface, draws: np.ndarray) -> None:
    """Monte Carlo draws ``(J, N, 3)`` of (c1, c2, v) as dots, coloured by prediction step."""
    steps = draws.shape[1]
    for n in reversed(range(steps)):  # the nearest on top
        colour = blend(SAMPLE, BOX_FAR, n / max(steps - 1, 1))
        for x, y in draws[:, n, :2]:
            pygame.draw.circle(surface, colour, surface.vec2pix((x, y)), 1)


def draw_disc(surface: WorldSurface, x: float, y: float, radius: float, colour: tuple[int, ...]) -> None:
    """The outline of a collision disc of ``radius`` [m] at ``(x, y)``."""
    pygame.draw.circle(surface, colour, surface.vec2pix((x, y)), max(surface.pix(radius), 2), 2)


def draw_text(target: pygame.Surface, lines: Sequence[str], font: pygame.font.Font) -> None:
    """Status lines at the top left, on a light box."""
    if not lines:
        return
    rendered = [font.render(line, True, TEXT) for line in lines]
    width = max(r.get_width() for r in rendered) + 12
    pygame.draw.rect(target, TEXT_BACKGROUND, pygame.Rect(0, 0, width, 18 * len(rendered) + 8))
    for i, r in enumerate(rendered):
        target.blit(r, (6, 5 + 18 * i))


class HighwayRenderer(Renderer):
    """``RiskCrossing-v0`` in highway-env's graphics (see the module docstring).

    The view, the window and ``close`` are the basic :class:`risk_env.render.rendering.Renderer`'s (so
    ``_to_px`` maps world to frame pixels alike); ``render`` takes the same arguments and returns
    ``(H, W, 3)`` uint8 in ``"rgb_array"`` mode. ``estimator``: the env's risk estimator's name
    (``"monte_carlo"`` adds the draws).
    """

    def __init__(
        self,
        scenario: Scenario,
        mode: str,
        fps: float,
        size: tuple[int, int] = SIZE,
        estimator: str = "exact",
        seed: int = SAMPLE_SEED,
    ) -> None:
        super().__init__(scenario, mode, fps, size)
        self.estimator = estimator
        self._rng = np.random.default_rng(seed)
        self._world = WorldSurface(size, 0, pygame.Surface(size))
        self._world.scaling = self._scale
        self._world.origin = self._centre - 0.5 * np.array(size) / self._scale
        self._road = Road(network=self._network(), vehicles=[], record_history=False)
        self._ego = Vehicle(
            self._road, [scenario.ego.start.x, scenario.ego.start.y], scenario.ego.start.theta
        )
        self._objects = [
            Vehicle(self._road, [o.start.x, o.start.y], o.start.theta, o.speed) for o in scenario.objects
        ]
        self._road.vehicles = [*self._objects, self._ego]

    def _network(self) -> RoadNetwork:
        """The reference arc (to the goal, then striped beyond it) and each object's course."""
        s = self.scenario
        path, net = s.path, RoadNetwork()
        x, y, theta = (float(c) for c in point(path, path.lambda_start))
        net.add_lane("start", "goal", arc_lane(x, y, theta, path.curvature, -path.lambda_start))
        gx, gy, gt = (float(c) for c in point(path, path.lambda_goal))
        striped = (LineType.STRIPED, LineType.STRIPED)
        net.add_lane("goal", "beyond", arc_lane(gx, gy, gt, path.curvature, BEYOND_GOAL, striped))
        for i, o in enumerate(s.objects):
            speed = max(abs(o.speed), 1e-6)
            length = speed * s.max_steps * s.dt
            curvature = o.turn_rate / speed if abs(o.turn_rate / speed) * length < math.pi else 0.0
            lane = arc_lane(o.start.x, o.start.y, o.start.theta, curvature, length, striped)
            net.add_lane(f"object {i}", f"crossed {i}", lane)
        return net

    def render(
        self,
        ego_pose: np.ndarray,
        ego_speed: float,
        object_measurements: np.ndarray,
        plan: np.ndarray | None = None,
        status: Sequence[str] = (),
    ) -> np.ndarray | None:
        """Draw one frame (arguments as :meth:`risk_env.render.rendering.Renderer.render`)."""
        s, world = self.scenario, self._world
        RoadGraphics.display(self._road, world)
        gx, gy, _ = point(s.path, s.path.lambda_goal)
        pygame.draw.circle(world, GOAL, world.vec2pix((float(gx), float(gy))), 5)

        measurements = np.atleast_2d(np.asarray(object_measurements, dtype=float))
        shown = list(zip(measurements, s.objects, s.uncertainties, strict=False))
        for measurement, _, u in shown:
            draw_beliefs(world, predict(s, measurement, uncertainty=u)[1:])
        if plan is not None and len(plan) > 0:
            draw_polyline(world, np.asarray(plan)[:, :2], PLAN)

        x, y, th = (float(c) for c in ego_pose[:3])
        crashed = [math.hypot(x - m[0], y - m[1]) <= s.ego.radius + o.radius for m, o, _ in shown]
        for vehicle, (ox, oy, oth, ov, _), hit in zip(self._objects, measurements, crashed, strict=False):
            vehicle.position = np.array([ox, oy])
            vehicle.heading, vehicle.speed = oth, ov
            vehicle.color = CRASHED if hit else OBJECT
        self._ego.position, self._ego.heading, self._ego.speed = np.array([x, y]), th, ego_speed
        self._ego.color = CRASHED if any(crashed) else EGO
        self._road.vehicles = [*self._objects[: len(shown)], self._ego]  # absent objects not drawn
        RoadGraphics.display_traffic(self._road, world, offscreen=True)
        for measurement, obj, _ in shown:
            draw_disc(world, float(measurement[0]), float(measurement[1]), obj.radius, DISC)
        draw_disc(world, x, y, s.ego.radius, DISC)
        if self.estimator == "monte_carlo":  # over the vehicles: where the objects may be
            for measurement, _, u in shown:
                one = predict_array(s, measurement, uncertainty=u)
                draw_samples(world, one.sample(self._rng, s.mc_samples)[:, 1:])  # (J, N, 3)

        self._surface.blit(pygame.transform.flip(world, False, True), (0, 0))  # y up
        draw_text(self._surface, status, self._font)
        if self.mode == "human":
            self._show()
            return None
        return frame_array(self._surface)


def render_scene(
    env: Any,
    size: tuple[int, int] = (600, 600),
    scaling: float | None = None,
    centre: Sequence[float] | None = None,
    route: np.ndarray | None = None,
    plan: np.ndarray | None = None,
    beliefs: Sequence[Belief] | None = None,
    highlight: Sequence[float] | None = None,
    status: Sequence[str] = (),
    mixtures: Sequence[Mixture] | None = None,
) -> np.ndarray:
    """A frame ``(H, W, 3)`` uint8 of a highway-env env's road and traffic, in highway-env's own
    frame (y down), with overlays: a ``route (M, 2)`` line, the ``beliefs`` (boxes), the
    ``mixtures``' modes (:func:`draw_mixtures`), a ``plan (M, 2)``, a disc outline around the point
    ``highlight (3,) = (x, y, radius)``, status text.
    The controlled vehicle is drawn in highway-env's ego colour (green; red once crashed).
    ``scaling`` [px/m] defaults to the env's, ``centre`` [m] to the controlled vehicle."""
    base = getattr(env, "unwrapped", env)
    pygame.font.init()
    world = WorldSurface(size, 0, pygame.Surface(size))
    world.scaling = float(scaling or base.config.get("scaling", WorldSurface.INITIAL_SCALING))
    if centre is None:
        centre = base.vehicle.position if base.vehicle is not None else (0.0, 0.0)
    world.origin = np.asarray(centre, dtype=float) - 0.5 * np.array(size) / world.scaling
    RoadGraphics.display(base.road, world)
    RoadGraphics.display_road_objects(base.road, world, offscreen=True)
    if route is not None:
        draw_polyline(world, route, ROUTE, 1, dots=False)
    if beliefs is not None:
        draw_beliefs(world, beliefs)
    if mixtures is not None:
        draw_mixtures(world, mixtures)
    ego = base.vehicle
    own = getattr(ego, "color", None) if ego is not None else None
    if ego is not None and not ego.crashed:
        ego.color = EGO  # drawn in highway-env's ego colour whatever its class; restored below
    try:
        RoadGraphics.display_traffic(base.road, world, offscreen=True)
    finally:
        if ego is not None:
            if own is None:
                ego.__dict__.pop("color", None)
            else:
                ego.color = own
    if plan is not None and len(plan) > 0:
        draw_polyline(world, np.asarray(plan)[:, :2], PLAN)
    if highlight is not None:
        draw_disc(world, highlight[0], highlight[1], highlight[2], BOX_NEAR)
    draw_text(world, status, pygame.font.Font(None, 20))
    return frame_array(world)
