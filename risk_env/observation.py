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

Bounds: the observation Box is fixed, the same for every scenario: :data:`POSITION_BOUND` for
positions, arc length and position errors, pi for the wrapped headings, :data:`RATE_BOUND` for
speeds, turn rates and the speed error (:func:`bounds`). A Box derived from each scenario would
change with it: saved policies (the PPO models) would no longer match, and randomised episodes
and batched copies could not share one space. So the scenario guarantees the fit instead:
:class:`~risk_env.scenario.Scenario` rejects, naming the fields, any scenario whose observations
could leave the Box within ``max_steps`` steps, for any actions and with the object moving either
way (``object_motion="paper"`` or ``"sampled"``); see
:meth:`~risk_env.scenario.Scenario.observation_reach` for the worst cases. Stepping past an
episode's end raises, so no episode runs longer. (``randomize=True`` draws each episode's
scenario through the same check: a draw that could leave the Box raises at ``reset``.)
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

POSITION_BOUND = 1e5
"""Bound [m] of positions, the arc length and the position errors in the observation Box."""
RATE_BOUND = 1e3
"""Bound [m/s, rad/s] of speeds, turn rates and the speed error in the observation Box."""
HEADINGS = (2, 7, 13)
"""Indices of the wrapped headings (ego, object, heading error), bounded by pi."""

SLICES: dict[str, slice] = {
    "ego_pose": EGO_POSE,
    "ego_input": EGO_INPUT,
    "object_pose": OBJECT_POSE,
    "object_input": OBJECT_INPUT,
    "progress": slice(PROGRESS, PROGRESS + 1),
    "path_error": PATH_ERROR,
}


def bounds() -> np.ndarray:
    """Upper bounds of the observation Box (the lower ones are their negatives), float32 ``(15,)``."""
    high = np.full(SIZE, POSITION_BOUND, dtype=np.float32)
    high[list(HEADINGS)] = np.pi
    high[EGO_INPUT] = RATE_BOUND
    high[OBJECT_INPUT] = RATE_BOUND
    high[PATH_ERROR.stop - 1] = RATE_BOUND  # speed error
    return high


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
