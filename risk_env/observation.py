r"""The observation vector of ``RiskCrossing-v0``: its layout, shared by the env and the agents.

``obs`` is float32 of length :func:`size` ``(K)`` $= 10 + 6 K$: the ego's part, then $K$ object
slots ($K$ = the env's ``object_slots``, fixed at construction; by default the scenario's number
of objects). Object $i$ of the scenario fills slot $i$; a slot without an object is *absent*: its flag
is 0 and its other five entries are 0 too (never a stand-in position).

| index | name | unit |
| --- | --- | --- |
| 0, 1, 2 | ego pose $c_1, c_2, \theta$ | m, m, rad ($\theta$ wrapped to $[-\pi, \pi)$) |
| 3, 4 | ego's last applied input $v, \omega$ | m/s, rad/s |
| 5 | $\lambda$: arc length of the ego's closest path point | m (goal at 0) |
| 6..9 | path error $e_k = (c_1 - c_{1,P}, c_2 - c_{2,P}, \theta - \theta_P, v - v_{ref})$ | m, m, rad, m/s |
| 10 + 6 i | slot $i$'s presence flag: 1.0 an object is there, 0.0 absent | - |
| 11 + 6 i, 12 + 6 i, 13 + 6 i | object $i$'s measured pose $c_1, c_2, \theta$ | m, m, rad (wrapped) |
| 14 + 6 i, 15 + 6 i | object $i$'s measured inputs $v, \omega$ | m/s, rad/s |

for $i = 0, \dots, K-1$. With one slot (the paper's scene) the observation has :data:`SIZE` = 16 entries
and the object at 11..15 (:data:`OBJECT`).

Read observations with :func:`split`, which names the parts, checks the slot count and the
flags, and gives the agents what they read: ``objects`` ``(K, 5)`` measurements ``(c1, c2,
theta, v, omega)`` as :func:`risk_env.predict` takes them, ``present`` ``(K,)`` bools and
``object_measurement``, the first present object's (what a single-object agent plans against).

Bounds: the observation Box is fixed, the same for every scenario: :data:`POSITION_BOUND` for
positions, arc length and position errors, $\pi$ for the wrapped headings, :data:`RATE_BOUND` for
speeds, turn rates and the speed error, [0, 1] for the flags (:func:`bounds`). A Box derived from
each scenario would change with it: saved policies (the PPO models) would no longer match, and
randomised episodes and batched copies could not share one space. So the scenario guarantees the
fit instead: :class:`~risk_env.scenario.scenario.Scenario` rejects, naming the fields, any scenario whose
observations could leave the Box within ``max_steps`` steps, for any actions and with every
object moving either way (``object_motion="paper"`` or ``"sampled"``); see
:meth:`~risk_env.scenario.scenario.Scenario.observation_reach` for the worst cases. Stepping past an
episode's end raises, so no episode runs longer. (``randomize=True`` draws each episode's
scenario through the same check: a draw that could leave the Box raises at ``reset``.)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from risk_env.models.ops import NUMPY

EGO_POSE = slice(0, 3)
EGO_INPUT = slice(3, 5)
PROGRESS = 5
PATH_ERROR = slice(6, 10)
EGO_SIZE = 10
"""Entries before the first object slot."""
SLOT_SIZE = 6
"""Entries per object slot: flag, c1, c2, theta, v, omega."""
SIZE = EGO_SIZE + SLOT_SIZE
"""Length of an observation with one object slot."""
PRESENT = EGO_SIZE
"""The first slot's presence flag."""
OBJECT_POSE = slice(EGO_SIZE + 1, EGO_SIZE + 4)
"""The first slot's pose (c1, c2, theta)."""
OBJECT_INPUT = slice(EGO_SIZE + 4, EGO_SIZE + SLOT_SIZE)
"""The first slot's inputs (v, omega)."""
OBJECT = slice(EGO_SIZE + 1, EGO_SIZE + SLOT_SIZE)
"""The first slot's measurement ``(c1, c2, theta, v, omega)`` that :func:`risk_env.predict` takes."""

POSITION_BOUND = 1e5
"""Bound [m] of positions, the arc length and the position errors in the observation Box."""
RATE_BOUND = 1e3
"""Bound [m/s, rad/s] of speeds, turn rates and the speed error in the observation Box."""
HEADINGS = (2, 8, 13)
"""Indices of the wrapped headings with one slot (ego, heading error, object), bounded by pi."""


def size(slots: int) -> int:
    """Length of an observation with ``slots`` object slots: ``10 + 6 slots``."""
    return EGO_SIZE + SLOT_SIZE * slots


def slot_count(length: int) -> int:
    """The number of object slots of an observation of ``length`` entries; ``ValueError`` for a
    length no slot count gives."""
    slots, rest = divmod(length - EGO_SIZE, SLOT_SIZE)
    if length < SIZE or rest:
        raise ValueError(
            f"an observation has 10 + 6 K entries for K >= 1 object slots (16, 22, 28, ...), got {length}"
        )
    return slots


def slot(i: int) -> slice:
    """Slot ``i``'s entries: flag, c1, c2, theta, v, omega."""
    start = EGO_SIZE + SLOT_SIZE * i
    return slice(start, start + SLOT_SIZE)


def slices(slots: int = 1) -> dict[str, slice]:
    """Names of the observation's parts with ``slots`` object slots: the ego's, ``"present"``
    (the flags, a strided slice), and ``"object_i"`` for each slot (flag, c1, c2, theta, v, omega)."""
    out = {
        "ego_pose": EGO_POSE,
        "ego_input": EGO_INPUT,
        "progress": slice(PROGRESS, PROGRESS + 1),
        "path_error": PATH_ERROR,
        "present": slice(EGO_SIZE, size(slots), SLOT_SIZE),
    }
    out.update({f"object_{i}": slot(i) for i in range(slots)})
    return out


SLICES: dict[str, slice] = slices(1)
""":func:`slices` of one slot."""


def bounds(slots: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the observation Box, float32 ``(size(slots),)`` each."""
    high = np.full(size(slots), POSITION_BOUND, dtype=np.float32)
    high[[2, PATH_ERROR.start + 2]] = np.pi  # ego heading, heading error
    high[EGO_INPUT] = RATE_BOUND
    high[PATH_ERROR.stop - 1] = RATE_BOUND  # speed error
    low = -high
    for i in range(slots):
        start = EGO_SIZE + SLOT_SIZE * i
        low[start], high[start] = 0.0, 1.0  # the flag
        low[start + 3], high[start + 3] = -np.pi, np.pi  # the heading
        low[start + 4 : start + 6], high[start + 4 : start + 6] = -RATE_BOUND, RATE_BOUND
    return low, high


def action_bounds(ego: Any) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the action Box, float32 ``(2,)`` each: ``(v_min, -omega_max)`` and
    ``(v_max, omega_max)`` of ``ego`` (a :class:`~risk_env.scenario.parts.Ego`) [m/s, rad/s]."""
    low = np.array([ego.v_min, -ego.omega_max], dtype=np.float32)
    return low, np.array([ego.v_max, ego.omega_max], dtype=np.float32)


class Observation(NamedTuple):
    """One observation split into named parts (float64 arrays)."""

    ego_pose: np.ndarray
    """``(3,)`` c1 [m], c2 [m], theta [rad] (wrapped)."""
    ego_input: np.ndarray
    """``(2,)`` the last applied v [m/s], omega [rad/s]."""
    progress: float
    r"""$\lambda$ [m], the arc length of the closest path point."""
    path_error: np.ndarray
    """``(4,)`` e [m, m, rad, m/s]."""
    objects: np.ndarray
    """``(K, 5)`` each slot's measurement ``(c1, c2, theta, v, omega)`` (zeros where absent)."""
    present: np.ndarray
    """``(K,)`` bool: whether slot i holds an object."""

    @property
    def slots(self) -> int:
        """K, the number of object slots."""
        return len(self.present)

    @property
    def measurements(self) -> np.ndarray:
        """``(M, 5)`` the measurements of the present objects, in slot order."""
        return self.objects[self.present]

    @property
    def object_measurement(self) -> np.ndarray:
        """``(5,)`` ``(c1, c2, theta, v, omega)`` of the first present object, as
        :func:`risk_env.predict` takes it; ``ValueError`` when no slot holds one."""
        index = np.flatnonzero(self.present)
        if index.size == 0:
            raise ValueError(f"the observation holds no object: all {self.slots} slot(s) are absent")
        return self.objects[index[0]]

    @property
    def object_pose(self) -> np.ndarray:
        """``(3,)`` the first present object's pose."""
        return self.object_measurement[:3]

    @property
    def object_input(self) -> np.ndarray:
        """``(2,)`` the first present object's inputs."""
        return self.object_measurement[3:]


def split(obs: np.ndarray, slots: int | None = None) -> Observation:
    """Name the parts of one observation ``(10 + 6 K,)``.

    ``slots``: the K the caller expects (None: any, read from the length). Raises ``ValueError``
    on a wrong length or slot count, a NaN, a flag other than 0 or 1, or an absent slot with
    nonzero entries."""
    obs = np.asarray(obs, dtype=float)
    if obs.ndim != 1:
        raise ValueError(f"observation must be one vector (10 + 6 K,), got shape {obs.shape}")
    found = slot_count(obs.shape[0])
    if slots is not None and found != slots:
        raise ValueError(
            f"observation has {found} object slot(s) ({obs.shape[0]} entries), expected {slots}"
            f" ({size(slots)} entries): build the agent for the env's object_slots"
        )
    if not np.all(np.isfinite(obs)):
        raise ValueError(f"observation has non-finite entries: {obs}")
    table = obs[EGO_SIZE:].reshape(found, SLOT_SIZE)
    flags = table[:, 0]
    present = flags == 1.0
    if not np.all(present | (flags == 0.0)):
        raise ValueError(f"observation slot flags must be 1.0 (present) or 0.0 (absent), got {flags}")
    empty = ~present & np.any(table[:, 1:] != 0.0, axis=1)
    if np.any(empty):
        raise ValueError(
            f"observation slot(s) {np.flatnonzero(empty).tolist()} are marked absent but hold nonzero"
            " entries (absent slots are all zeros)"
        )
    return Observation(
        obs[EGO_POSE], obs[EGO_INPUT], float(obs[PROGRESS]), obs[PATH_ERROR], table[:, 1:], present
    )


def build(
    ego_pose: Sequence[float],
    ego_input: Sequence[float],
    progress: float,
    path_error: Sequence[float],
    objects: Sequence[Sequence[float]] | np.ndarray,
    slots: int | None = None,
) -> np.ndarray:
    r"""One observation ``(10 + 6 K,)`` float32 from its parts, as the env lays it out: the ego's
    pose ``(3,)`` and last input ``(2,)``, lambda [m], the path error ``(4,)``, and the
    measurements ``(M, 5)`` of the present objects (c1, c2, theta, v, omega) in slots 0..M-1, the
    other ``slots - M`` slots absent ($K$ = ``slots``, default $M$). Headings are wrapped to
    $[-\pi, \pi)$. For observations made outside the env (:mod:`risk_env.highway.adapter`)."""
    measured = np.asarray(objects, dtype=float).reshape(-1, SLOT_SIZE - 1)
    slots = len(measured) if slots is None else slots
    if len(measured) > slots:
        raise ValueError(f"{len(measured)} objects do not fit {slots} slot(s): none is dropped silently")
    out = np.zeros(size(slots))
    out[EGO_POSE], out[EGO_INPUT], out[PROGRESS], out[PATH_ERROR] = ego_pose, ego_input, progress, path_error
    table = out[EGO_SIZE:].reshape(slots, SLOT_SIZE)
    table[: len(measured), 0] = 1.0
    table[: len(measured), 1:] = measured
    heads = [2, *(EGO_SIZE + 3 + SLOT_SIZE * i for i in range(len(measured)))]
    out[heads] = NUMPY.wrap_angle(out[heads])
    return out.astype(np.float32)
