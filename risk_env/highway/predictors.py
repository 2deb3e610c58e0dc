"""The predictor of the other vehicles in a highway-env world, by name or instance:
``"lane"`` (:class:`risk_env.highway.lanes.LanePredictor`, on the env's road network: the map),
``"lane+interval"`` (the same with the interval prediction over highway-env's IDM parameters, the
env's controlled vehicle taking part as the ego),
``"constant"`` or None (the paper's, built into the risk and the MPCs), or any
:class:`~risk_env.prediction.predictors.Predictor`; and the one the junction gate
(:mod:`risk_env.highway.gate`) hands its agents, :class:`GatePredictor`: their own for every road
user but its virtual object, a road user standing at the stop line (:func:`standing`), told apart
from the observed ones by :func:`is_virtual`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from risk_env import checks
from risk_env.highway.common import policy_period, unwrapped_highway, vehicle_measurement
from risk_env.highway.lanes.follow import Leaders, follow_leaders
from risk_env.highway.lanes.predictor import EgoPlan, LanePredictor
from risk_env.prediction.belief import Belief
from risk_env.prediction.mixture import Mixture
from risk_env.prediction.predictors import PREDICTOR_NAMES, Predictor

HIGHWAY_PREDICTORS: tuple[str, ...] = PREDICTOR_NAMES
"""The predictors a highway-env world offers by name: ``"constant"``, ``"lane"`` and
``"lane+interval"``."""


def highway_predictor(
    predictor: str | Predictor | None, env: Any, pieces: int = 1, intervals: Any = None
) -> Predictor | None:
    """The predictor named ``predictor`` for ``env``'s road network and step, an instance as is,
    or None for the paper's (``None`` or ``"constant"``); an unknown name raises ``ValueError``
    naming it. ``pieces``: the lane predictors' P (bands along each route, one mode each);
    ``intervals``: ``"lane+interval"``'s :class:`~risk_env.highway.lanes.interval.IntervalModel`
    (None: its defaults)."""
    if predictor is None or isinstance(predictor, Predictor):
        return predictor
    name = checks.text("predictor", predictor, HIGHWAY_PREDICTORS)
    if name == "constant":
        return None

    network, dt = unwrapped_highway(env).road.network, policy_period(env)
    if name == "lane+interval":
        return LanePredictor(
            network, dt, pieces=pieces, longitudinal="interval", intervals=intervals, ego=ego_reader(env)
        )
    if intervals is not None:
        raise ValueError(f"intervals need the predictor 'lane+interval', got {name!r}")
    return LanePredictor(network, dt, pieces=pieces)


def ego_reader(env: Any) -> Callable[[], np.ndarray | None]:
    """A callable returning the measurement (:func:`~risk_env.highway.common.vehicle_measurement`)
    of ``env``'s controlled vehicle now (None when there is none): the interval prediction's ego."""

    def read() -> np.ndarray | None:
        vehicle = getattr(unwrapped_highway(env), "vehicle", None)
        return None if vehicle is None else vehicle_measurement(vehicle)

    return read


VIRTUAL_SIGMA = 0.05
"""Standard deviation [m] of the virtual object's position (and [m/s] of its speed)."""
VIRTUAL_HALF = 0.15
"""Half width [m] of its truncation box."""
SIGNAL_MATCH = 0.05
"""Largest distance [m] between a row an agent's predictor is asked about and an observed road user
for the row to get that road user's turn signal (float32 observations round by far less)."""
MATCH = 1e-3
"""Largest difference (float32 observation rounding) between a measurement and the virtual one."""


class GateError(ValueError):
    """A bad value for the junction gate (names the parameter and what was expected)."""


def is_virtual(rows: np.ndarray, virtual: np.ndarray | None) -> np.ndarray:
    """``(m,)`` which of the measurements ``rows (m, 5)`` are ``virtual`` (within :data:`MATCH`)."""
    rows = np.asarray(rows, dtype=float).reshape(-1, 5)
    if virtual is None:
        return np.zeros(len(rows), dtype=bool)
    return np.all(np.abs(rows - virtual[None, :]) <= MATCH, axis=1)


def standing(measurement: np.ndarray, steps: int) -> Mixture:
    """The virtual object's belief: at ``measurement``'s position over n = 0..``steps``, speed 0,
    spread :data:`VIRTUAL_SIGMA` truncated at :data:`VIRTUAL_HALF`."""
    n = steps + 1
    m = np.asarray(measurement, dtype=float)
    full = lambda value: np.full(n, float(value))  # noqa: E731
    belief = Belief(
        x=full(m[0]), y=full(m[1]), theta=full(m[2]), speed=full(0.0),
        sigma_x=full(VIRTUAL_SIGMA), sigma_y=full(VIRTUAL_SIGMA), sigma_v=full(VIRTUAL_SIGMA),
        half_x=full(VIRTUAL_HALF), half_y=full(VIRTUAL_HALF),
        v_lo=full(-VIRTUAL_HALF), v_hi=full(VIRTUAL_HALF), frame=full(m[2]),
    )  # fmt: skip
    return Mixture.single(belief, "stop line")


class GatePredictor(Predictor):
    """``inner`` for every road user but the gate's virtual object, which stands still
    (:func:`standing`); the virtual object is left out of ``inner``'s scene (nobody yields to it)."""

    name = "gate"

    def __init__(self, inner: Predictor) -> None:
        if not isinstance(inner, Predictor):
            raise GateError(f"inner must be a Predictor, got {checks.describe(inner)}")
        self.inner = inner
        self.max_modes = inner.max_modes
        self.virtual: np.ndarray | None = None
        """The virtual object's measurement this step, or None (the gate is open)."""
        self.signals: tuple[np.ndarray, list] | None = None
        """This step's observed road users ``(m, 5)`` and their turn signals (one ``(2,)`` or None
        each), or None: passed on to a lane predictor for the rows it is asked about."""
        self.ego_plan: EgoPlan | None = None
        """What the ego does this step for a lane predictor's prediction given it (the gate's
        ``given_ego`` and open: it drives its route), or None (it brakes)."""
        self.leaders: Leaders | None = None
        """The ego's route, position and corridor this step when the road users ahead on its route are
        boxes it follows (:func:`~risk_env.highway.lanes.follow.follow_leaders`), else None."""

    def predict(self, measurement: Any, steps: int) -> Mixture:
        return self.predict_scene(np.asarray(measurement, dtype=float)[None], steps)[0]

    def predict_scene(self, measurements: Any, steps: int) -> list[Mixture]:
        rows = np.asarray(measurements, dtype=float).reshape(-1, 5)
        virtual = is_virtual(rows, self.virtual)
        real_rows = rows[~virtual]
        inner = self._inner(real_rows, steps) if len(real_rows) else []
        real = iter(inner if self.leaders is None else follow_leaders(inner, self.leaders))
        return [standing(row, steps) if v else next(real) for row, v in zip(rows, virtual, strict=True)]

    def _inner(self, rows: np.ndarray, steps: int) -> list[Mixture]:
        """``inner``'s mixtures of ``rows``; a lane predictor is also given each row's turn signal
        when it is one of this step's observed road users (within :data:`SIGNAL_MATCH`), and
        :attr:`ego_plan`."""
        if not isinstance(self.inner, LanePredictor):
            return self.inner.predict_scene(rows, steps)
        if self.signals is None:
            return self.inner.predict_scene(rows, steps, ego_plan=self.ego_plan)
        seen, signals = self.signals
        gap = np.hypot(rows[:, None, 0] - seen[None, :, 0], rows[:, None, 1] - seen[None, :, 1])
        nearest = np.argmin(gap, axis=1) if len(seen) else np.zeros(len(rows), dtype=int)
        mine = [
            signals[k] if len(seen) and gap[i, k] <= SIGNAL_MATCH else None for i, k in enumerate(nearest)
        ]
        return self.inner.predict_scene(rows, steps, signals=mine, ego_plan=self.ego_plan)

    def __repr__(self) -> str:
        return f"GatePredictor({self.inner!r})"
