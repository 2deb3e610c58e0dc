"""Input checks shared by the scenario, the envs, the highway-env wrapper and the agents.

Each check names the value it rejects and says what it expected. Numbers must be *real*: Python
and numpy ints and floats pass; bools, strings, complex numbers and ``None`` do not (nothing is
parsed or cast silently). Integers must be of an integral type (``int``, ``np.int64``, ...), not
bools and not floats, not even ``4.0``.

The array checks are on the env's step path and cheap: a float or int ndarray passes after one
``dtype.kind`` test.

>>> real("risk_tolerance", np.float32(500))
500.0
>>> real("risk_tolerance", "500")
Traceback (most recent call last):
...
TypeError: risk_tolerance must be a real number (int or float), got '500' (str)
"""

from __future__ import annotations

import difflib
import math
import numbers
import operator
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

REAL_KINDS = "fiu"
"""numpy dtype kinds of real numbers: float, signed and unsigned integer (not bool, not complex)."""
ACTION_TOLERANCE = 1e-6
"""Actions may exceed a limit by this much relative to it, and by at least this much [m/s, rad/s]:
the float32 action Box rounds its bounds by up to 6e-8 relative. They are applied as given."""
_REAL_ONLY = "; only real numbers (ints and floats) pass"
_KIND_NAMES = {"b": "bools", "c": "complex numbers", "U": "strings", "S": "bytes", "O": "dtype object"}


def slack(limit: float) -> float:
    """How far an action may exceed ``limit`` (:data:`ACTION_TOLERANCE`, relative, at least absolute)."""
    return ACTION_TOLERANCE * max(1.0, abs(limit))


def describe(value: Any) -> str:
    """``repr`` of ``value`` with its type, shortened: ``'500' (str)``."""
    shown = " ".join(repr(value).split())  # arrays print over several lines
    if len(shown) > 80:
        shown = shown[:77] + "..."
    return f"{shown} ({type(value).__name__})"


def is_real(value: Any) -> bool:
    """Whether ``value`` is one real number: an int or float of Python or numpy (or a 0-d real
    array), not a bool."""
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, numbers.Real):
        return True
    return isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in REAL_KINDS


def real(name: str, value: Any) -> float:
    """``value`` as a float if it is a real number (:func:`is_real`), else ``TypeError`` naming ``name``."""
    if not is_real(value):
        raise TypeError(f"{name} must be a real number (int or float), got {describe(value)}")
    try:
        return float(value)
    except OverflowError:
        raise ValueError(f"{name} must be finite, got {value!r}") from None


def finite(name: str, value: Any) -> float:
    """``value`` as a float if it is a finite real number, else an error naming ``name``."""
    out = real(name, value)
    if not math.isfinite(out):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return out


def positive(name: str, value: Any, strict: bool = True) -> float:
    """``value`` as a float if it is finite and > 0 (``strict=False``: >= 0), else an error naming
    ``name``."""
    out = finite(name, value)
    if out < 0 or (strict and out == 0):
        bound = "> 0" if strict else ">= 0"
        raise ValueError(f"{name} must be {bound}, got {value!r}")
    return out


def within_severity(name: str, value: float, severity: str, bound: float, unit: str) -> float:
    """``value`` if it is at most ``bound``, the largest per-step risk of the severity named
    ``severity`` [``unit``]; else ``ValueError`` naming it (a tolerance above it is in another unit)."""
    if value > bound:
        raise ValueError(
            f"{name} {value:g} exceeds {bound:g}, the largest per-step risk of the {severity!r} severity"
            f" [{unit}]: give it in that severity's own unit"
        )
    return value


def finite_reals(name: str, value: Any, length: int) -> tuple[float, ...]:
    """:func:`reals`, each entry finite; errors name ``name[i]``."""
    out = reals(name, value, length)
    for i, v in enumerate(out):
        finite(f"{name}[{i}]", v)
    return out


def integer(name: str, value: Any, minimum: int | None = None) -> int:
    """``value`` as an int if its type is integral (Python's or numpy's, not bool, not float),
    else ``TypeError``; ``ValueError`` below ``minimum``."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be an integer, got the bool {value!r}")
    try:
        out = operator.index(value)
    except TypeError:
        raise TypeError(f"{name} must be an integer (int or numpy integer), got {describe(value)}") from None
    if minimum is not None and out < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return out


def text(name: str, value: Any, choices: Sequence[str]) -> str:
    """``value`` if it is one of the strings ``choices``; else an error naming ``name``, with a
    suggestion for a near miss."""
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a string, one of {tuple(choices)}; got {describe(value)}")
    if value not in choices:
        close = difflib.get_close_matches(value, choices, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(f"unknown {name} {value!r}{hint}; expected one of {tuple(choices)}")
    return value


def flag(name: str, value: Any) -> bool:
    """``value`` if it is a bool (Python's or numpy's), else ``TypeError`` naming ``name``."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {describe(value)}")
    return bool(value)


def reals(name: str, value: Any, length: int) -> tuple[float, ...]:
    """``value`` as a tuple of ``length`` floats: a sequence or array of real numbers (a string is
    not one); errors name ``name`` and the entry."""
    if isinstance(value, np.ndarray) and value.ndim != 1 or not isinstance(value, Iterable):
        raise TypeError(f"{name} must be a sequence of {length} real numbers, got {describe(value)}")
    if isinstance(value, (str, bytes, Mapping)):
        raise TypeError(f"{name} must be a sequence of {length} real numbers, got {describe(value)}")
    items = list(value)
    if len(items) != length:
        raise ValueError(f"{name} must have {length} entries, got {len(items)}: {value!r}")
    for i, item in enumerate(items):
        if not is_real(item):
            raise TypeError(
                f"{name}[{i}] must be a real number (int or float), got {describe(item)} in {value!r}"
            )
    return tuple(float(item) for item in items)


def real_array(value: Any, name: str, expected: str) -> np.ndarray:
    """``value`` as a float64 array if every entry is a real number; else ``ValueError`` naming
    ``name``, the value and the ``expected`` form (e.g. ``"2 numbers (v [m/s], omega [rad/s])"``).

    Rejects bools, strings, complex numbers and objects; shapes are the caller's to check. A float
    or int ndarray passes after one dtype test.
    """
    if type(value) is np.ndarray and value.dtype.kind in REAL_KINDS:  # the fast path
        return np.asarray(value, dtype=np.float64)
    if isinstance(value, (list, tuple)) and _has_bool(value):
        # numpy would turn [True, 1.5] into floats: look for Python and numpy bools first
        raise ValueError(f"{name} must be {expected}, got {describe(value)} with bools{_REAL_ONLY}")
    try:
        a = np.asarray(value)
    except (TypeError, ValueError) as exc:  # e.g. ragged nesting
        raise ValueError(f"{name} must be {expected}, got {describe(value)} ({exc})") from None
    kind = a.dtype.kind
    if kind not in REAL_KINDS:
        found = _KIND_NAMES.get(kind, f"dtype {a.dtype}")
        raise ValueError(f"{name} must be {expected}, got {describe(value)} with {found}{_REAL_ONLY}")
    return a.astype(np.float64, copy=False)


def ego_action(action: Any, ego: Any) -> tuple[float, float]:
    """``action`` as ``(v, omega)`` floats if the env's action Box of ``ego`` (a
    :class:`~risk_env.scenario.parts.Ego`) holds it (up to :func:`slack`); else ``ValueError`` naming it."""
    a = real_array(action, "action", "2 numbers (v [m/s], omega [rad/s])")
    if a.shape != (2,):
        raise ValueError(
            f"action must have shape (2,) = (v [m/s], omega [rad/s]), got shape {a.shape}: {action!r}"
        )
    v, omega = float(a[0]), float(a[1])
    if not (math.isfinite(v) and math.isfinite(omega)):
        raise ValueError(f"action must be finite, got (v, omega) = ({v}, {omega})")
    if not (ego.v_min <= v <= ego.v_max or ego.v_min - slack(ego.v_min) <= v <= ego.v_max + slack(ego.v_max)):
        raise ValueError(
            f"action v = {v} m/s lies outside [v_min, v_max] = [{ego.v_min}, {ego.v_max}]"
            " (the env clips nothing)"
        )
    if not (abs(omega) <= ego.omega_max or abs(omega) <= ego.omega_max + slack(ego.omega_max)):
        raise ValueError(
            f"action omega = {omega} rad/s lies outside [-omega_max, omega_max] ="
            f" [{-ego.omega_max}, {ego.omega_max}] (the env clips nothing)"
        )
    return v, omega


def seeds(seed: Any, n: int) -> list[int | None]:
    """Seeds of ``n`` copies from ``None``, one integer ``s`` (copies get ``s + i``) or ``n`` of
    them (integers or ``None``); integers of any integral type, >= 0."""
    if seed is None:
        return [None] * n
    if not isinstance(seed, (list, tuple, np.ndarray)):
        first = integer("seed", seed, minimum=0)
        return [first + i for i in range(n)]
    out = list(seed)
    if len(out) != n:
        raise ValueError(f"seed must be None, an int or a list of {n} seeds, got {len(out)}: {seed!r}")
    return [None if s is None else integer(f"seed[{i}]", s, minimum=0) for i, s in enumerate(out)]


def _has_bool(items: list | tuple) -> bool:
    """Whether nested lists and tuples hold a Python or numpy bool."""
    for item in items:
        if isinstance(item, (bool, np.bool_)):
            return True
        if isinstance(item, (list, tuple)) and _has_bool(item):
            return True
    return False


def space_action(action: Any, space: spaces.Space, name: str = "action") -> None:
    """Check an action for a Gymnasium ``space`` before an env sees it.

    ``Box``: finite real numbers (:func:`real_array`) of the space's shape, a single number for a
    one-entry Box (the range is left to the env, which may clip on purpose); ``Discrete``: an
    integer in range; ``Tuple``: each part against its space. Other spaces: ``space.contains``.
    """
    if isinstance(space, spaces.Box):
        a = real_array(action, name, f"numbers of shape {space.shape}")
        if a.shape != space.shape and not (a.size == 1 and space.shape in ((), (1,))):
            raise ValueError(f"{name} must have shape {space.shape}, got shape {a.shape}: {action!r}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite, got {action!r}")
    elif isinstance(space, spaces.Discrete):
        if isinstance(action, np.ndarray) and action.ndim == 0:
            action = action[()]
        index = integer(name, action)
        if not space.start <= index < space.start + space.n:
            high = space.start + space.n
            raise ValueError(f"{name} must be an integer in [{space.start}, {high}), got {index}")
    elif isinstance(space, spaces.Tuple):
        if not isinstance(action, (tuple, list)) or len(action) != len(space.spaces):
            raise ValueError(f"{name} must be a tuple of {len(space.spaces)} actions, got {describe(action)}")
        for i, (part, sub) in enumerate(zip(action, space.spaces, strict=True)):
            space_action(part, sub, f"{name}[{i}]")
    elif not space.contains(action):
        raise ValueError(f"{name} {describe(action)} is not in the action space {space}")


def episode_end(collision: bool, goal: bool, steps: int, max_steps: int) -> str:
    """Why an episode ended, for the error raised on stepping past its end."""
    if collision:
        return f"terminated by a collision at step {steps}"
    if goal:
        return f"terminated at the goal at step {steps}"
    return f"truncated at max_steps = {max_steps}"


def batch_actions(actions: Any, copies: int) -> np.ndarray:
    """``actions`` of a batched env as a new float array ``(copies, 2)``; raises ``ValueError`` on
    a wrong shape or values that are not real numbers."""
    expected = f"numbers of shape ({copies}, 2)"
    a = np.array(real_array(actions, "actions", expected), dtype=float)  # a copy: changed later
    if a.shape != (copies, 2):
        raise ValueError(f"actions must have shape ({copies}, 2) = (v [m/s], omega [rad/s]), got {a.shape}")
    return a


def batch_actions_inside(
    a: np.ndarray, low: np.ndarray, high: np.ndarray, ego: Any, active: np.ndarray | None
) -> None:
    """Raise ``ValueError`` naming the stepping copies (``active``; None: all) whose actions
    ``a (B, 2)`` lie outside ``[low, high]`` (the Box, with its float32 slack) or are not finite;
    ``ego``'s limits are named in the message."""
    inside = (a >= low) & (a <= high)  # False for NaN
    if inside.all():
        return
    bad_rows = ~inside.all(axis=1)
    if active is not None:
        bad_rows &= active
    if not bad_rows.any():
        return
    non_finite = ~np.isfinite(a).all(axis=1)
    for name, bad in (("non-finite", non_finite), ("outside the action space", ~non_finite)):
        bad &= bad_rows
        if bad.any():
            rows = np.flatnonzero(bad)[:5].tolist()
            raise ValueError(
                f"actions of copies {rows} are {name}: {a[rows].tolist()} (bounds v in"
                f" [{ego.v_min}, {ego.v_max}] m/s, |omega| <= {ego.omega_max} rad/s;"
                " the env clips nothing)"
            )
