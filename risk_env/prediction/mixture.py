r"""A road user's belief over the horizon as a weighted mixture of modes.

A **mode** is one hypothesis of where the road user goes (a route, a manoeuvre): a sequence of
truncated Gaussians, one :class:`~risk_env.prediction.belief.Belief` per prediction step $n = 0, \dots, N$,
each with its mean, its standard deviations and truncation box in its own frame (``frame``, the
angle of its first axis) and its speed interval. A **mixture** holds the modes with weights
$w_m \ge 0$ that sum to 1: the road user follows mode $m$ with probability $w_m$.

The risk of a mixture is $R = \sum_m w_m R_m$ for the expected risks (exact, Monte Carlo): exact
by linearity of expectation, as the sum over objects is; the robust planner instead bounds the
worst case over every mode of weight at least a threshold
(:meth:`risk_env.risk.estimators.RiskEstimator.mixture_risk`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from risk_env.prediction.belief import Belief

WEIGHT_TOLERANCE = 1e-6
"""How far the weights of a mixture may sum from 1 (rounding of weights computed elsewhere)."""


@dataclass(frozen=True)
class Mode:
    r"""One hypothesis: ``beliefs`` with a leading step axis ``(N+1,)`` on every field ($n = 0, \dots, N$)
    and its weight $w_m$ in $[0, 1]$; ``label`` names it (``"straight"``, ``"left"``, ...)."""

    weight: float
    beliefs: Belief
    label: str = ""
    share: float = 1.0
    """The share in (0, 1] of its hypothesis (a route) this mode is: a predictor that splits a
    hypothesis into P pieces gives each 1/P of its weight; a threshold compares the hypothesis's
    weight, ``weight / share`` (:meth:`Mixture.above`)."""

    @property
    def steps(self) -> int:
        """$N$, the last prediction step."""
        return int(np.shape(self.beliefs.x)[0]) - 1

    def at(self, n: int) -> Belief:
        """The mode's belief at prediction step ``n`` (fields of floats)."""
        return Belief(**{f.name: float(np.asarray(getattr(self.beliefs, f.name))[n]) for f in fields(Belief)})


@dataclass(frozen=True)
class Mixture:
    r"""The modes of one road user's belief; their weights are $\ge 0$ and sum to 1.

    Raises ``ValueError`` naming the mode and field for a negative or NaN weight, weights that
    do not sum to 1 (beyond :data:`WEIGHT_TOLERANCE`), modes of different lengths, and a standard
    deviation or box half width that is negative or not finite.
    """

    modes: tuple[Mode, ...]

    def __post_init__(self) -> None:
        modes = tuple(self.modes)
        if not modes or not all(isinstance(m, Mode) for m in modes):
            raise ValueError(f"a Mixture needs at least one Mode, got {self.modes!r}")
        object.__setattr__(self, "modes", modes)
        for i, mode in enumerate(modes):
            w = mode.weight
            if not (isinstance(w, (int, float, np.floating, np.integer)) and math.isfinite(w) and w >= 0):
                raise ValueError(f"modes[{i}].weight must be a finite number >= 0, got {w!r}")
            if not (isinstance(mode.share, (int, float, np.floating)) and 0.0 < mode.share <= 1.0):
                raise ValueError(f"modes[{i}].share must lie in (0, 1], got {mode.share!r}")
            check_spreads(mode.beliefs, f"modes[{i}].beliefs")
        total = math.fsum(m.weight for m in modes)
        if abs(total - 1.0) > WEIGHT_TOLERANCE:
            raise ValueError(f"the modes' weights must sum to 1, got {total!r} ({[m.weight for m in modes]})")
        lengths = {m.steps for m in modes}
        if len(lengths) > 1:
            raise ValueError(f"the modes must cover the same prediction steps, got N = {sorted(lengths)}")

    @classmethod
    def single(cls, beliefs: Belief, label: str = "") -> Mixture:
        """One mode of weight 1 (the paper's prediction)."""
        return cls((Mode(1.0, beliefs, label),))

    @property
    def steps(self) -> int:
        """$N$, the last prediction step."""
        return self.modes[0].steps

    @property
    def weights(self) -> np.ndarray:
        """``(M,)`` the modes' weights."""
        return np.array([m.weight for m in self.modes])

    def __iter__(self) -> Iterator[Mode]:
        return iter(self.modes)

    def __len__(self) -> int:
        return len(self.modes)

    def most_likely(self) -> Mode:
        """The mode of largest weight (the first of equals)."""
        return self.modes[int(np.argmax(self.weights))]

    def at(self, n: int) -> list[tuple[float, Belief]]:
        """``[(w_m, belief of mode m at step n), ...]``."""
        return [(m.weight, m.at(n)) for m in self.modes]

    def above(self, threshold: float) -> tuple[Mode, ...]:
        """The modes whose hypothesis weighs at least ``threshold`` (in [0, 1]; ``weight / share``:
        every piece of a likely route), or the most likely one when none does."""
        if not (0.0 <= threshold <= 1.0):
            raise ValueError(f"the mode threshold must lie in [0, 1], got {threshold!r}")
        kept = tuple(m for m in self.modes if m.weight >= threshold * m.share)
        return kept or (self.most_likely(),)

    def sample_mode(self, uniform: float) -> Mode:
        """The mode a uniform draw on [0, 1) picks, by inverse transform over the weights."""
        return self.modes[_pick(self.weights, uniform)]

    @staticmethod
    def pick(modes: Sequence[tuple[float, Belief]], uniform: float) -> Belief:
        """The belief a uniform draw on [0, 1) picks from ``[(w_m, belief), ...]`` (:meth:`at`)."""
        return modes[_pick(np.array([w for w, _ in modes]), uniform)][1]


def _pick(weights: np.ndarray, uniform: float) -> int:
    """Inverse transform: the index whose weight interval holds ``uniform * sum(weights)``."""
    edges = np.cumsum(weights)
    return min(int(np.searchsorted(edges, uniform * edges[-1], side="right")), len(weights) - 1)


def check_spreads(belief: Belief, name: str) -> None:
    """Raise ``ValueError`` naming ``name.field`` when a standard deviation or box half width of
    ``belief`` is negative or not finite, or a mean is not finite."""
    for field in ("sigma_x", "sigma_y", "sigma_v", "half_x", "half_y"):
        value = np.asarray(getattr(belief, field), dtype=float)
        if not np.all(np.isfinite(value)) or np.any(value < 0):
            raise ValueError(f"{name}.{field} must be finite and >= 0, got {value}")
    for field in ("x", "y", "theta", "speed"):
        if not np.all(np.isfinite(np.asarray(getattr(belief, field), dtype=float))):
            raise ValueError(f"{name}.{field} must be finite, got {getattr(belief, field)}")


def stack_modes(modes: Sequence[Mode]) -> tuple[np.ndarray, np.ndarray]:
    """``(weights (M,), fields (M, N+1, F))`` of ``modes``, fields in ``Belief.as_array`` order."""
    return np.array([m.weight for m in modes]), np.stack([m.beliefs.as_array() for m in modes])


def belief_array(beliefs: Any) -> np.ndarray:
    """A belief's fields as ``(..., F)`` (a :class:`Belief` or an array already)."""
    return beliefs.as_array() if isinstance(beliefs, Belief) else np.asarray(beliefs, dtype=float)
