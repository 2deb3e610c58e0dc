"""The observation vector of ``RiskCrossing-v0``: its layout, shared by the env and the agents.

``obs`` is float32 of length :data:`SIZE`:

| index | name | unit |
| --- | --- | --- |
| 0, 1, 2 | ego pose c1, c2, theta | m, m, rad (theta wrapped to [-pi, pi)) |
| 3, 4 | ego's last applied input v, omega | m/s, rad/s |
| 5, 6, 7 | object's measured pose c1, c2, theta | m, m, rad (wrapped) |
| 8, 9 | object's measured inputs v, omega | m/s, rad/s |
| 10 | lambda: arc length of the ego's closest path point | m (goal at 0) |
| 11..14 | path error e_k = (c1 - c1_P, c2 - c2_P, theta - theta_P, v - v_ref) | m, m, rad, m/s |
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

EGO_POSE = slice(0, 3)
EGO_INPUT = slice(3, 5)
OBJECT_POSE = slice(5, 8)
OBJECT_INPUT = slice(8, 10)
OBJECT = slice(5, 10)
"""The object measurement ``(c1, c2, theta, v, omega)`` that :func:`risk_env.predict` takes."""
PROGRESS = 10
PATH_ERROR = slice(11, 15)
SIZE = 15

SLICES: dict[str, slice] = {
    "ego_pose": EGO_POSE,
    "ego_input": EGO_INPUT,
    "object_pose": OBJECT_POSE,
    "object_input": OBJECT_INPUT,
    "progress": slice(PROGRESS, PROGRESS + 1),
    "path_error": PATH_ERROR,
}


class Observation(NamedTuple):
    """One observation split into named parts (float64 arrays)."""

    ego_pose: np.ndarray
    ego_input: np.ndarray
    object_pose: np.ndarray
    object_input: np.ndarray
    progress: float
    path_error: np.ndarray

    @property
    def object_measurement(self) -> np.ndarray:
        """``(c1, c2, theta, v, omega)`` of the object, as :func:`risk_env.predict` takes it."""
        return np.concatenate([self.object_pose, self.object_input])


def split(obs: np.ndarray) -> Observation:
    """Name the parts of one observation ``(15,)``; raises on a wrong shape or a NaN."""
    obs = np.asarray(obs, dtype=float)
    if obs.shape != (SIZE,):
        raise ValueError(f"observation must have shape ({SIZE},), got {obs.shape}")
    if not np.all(np.isfinite(obs)):
        raise ValueError(f"observation has non-finite entries: {obs}")
    return Observation(
        obs[EGO_POSE],
        obs[EGO_INPUT],
        obs[OBJECT_POSE],
        obs[OBJECT_INPUT],
        float(obs[PROGRESS]),
        obs[PATH_ERROR],
    )
