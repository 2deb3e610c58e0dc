"""The lane predictor's modes: :class:`LaneMode`, and a route mode's parts, whole or held and
free (:class:`~risk_env.highway.lanes.interval.IntervalBounds`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from risk_env.highway.lanes.beliefs import Stretch
from risk_env.highway.lanes.interval import IntervalBounds
from risk_env.prediction.mixture import Mode

SPLIT_MIN = 1e-3
"""A held or free part of a mode less likely than this (within the mode) is left out."""


@dataclass(frozen=True)
class LaneMode(Mode):
    """A :class:`~risk_env.prediction.mixture.Mode` of the lane predictor, with the routes it stands
    for; its beliefs lie in the lane's frame (:attr:`Belief.frame
    <risk_env.prediction.belief.Belief.frame>`: ``sigma_x``/``half_x`` along the lane,
    ``sigma_y``/``half_y`` across it)."""

    routes: tuple[tuple[str, float], ...] = ()
    """The routes this mode stands for, ``(label, weight)``, labels as :meth:`Route.label
    <risk_env.highway.lanes.routes.Route.label>`; their weights sum to the mode's."""
    stretch: Stretch | None = None
    """The stretch of its route its boxes hold (None: not known)."""


def mode_parts(
    group: list[int], share: np.ndarray, s: np.ndarray, v: np.ndarray, bounds: IntervalBounds | None
) -> list[tuple[str, float, np.ndarray, np.ndarray, list | None]]:
    """``(suffix, weight within the mode, s, v, bounds)`` of a mode's parts: the mode whole, or
    held and free (:class:`~risk_env.highway.lanes.interval.IntervalBounds`), each with its
    routes' means where they lie within its bounds, else the bounds' middle."""
    if bounds is None:
        return [("", 1.0, s[group], v[group], None)]
    whole = [b[group] for b in bounds.union]
    chance = 0.0 if bounds.chance is None else float(share @ bounds.chance[group])
    if bounds.held is None or chance <= SPLIT_MIN:
        return [("", 1.0, s[group], v[group], whole)]
    out = []
    for suffix, weight, box in (
        (":held", chance, bounds.held),
        (":free", 1.0 - chance, bounds.free),
    ):
        if weight <= SPLIT_MIN or box is None:
            continue
        lo, hi, v_lo, v_hi = (b[group] for b in box)
        s_in = np.where((s[group] >= lo) & (s[group] <= hi), s[group], (lo + hi) / 2)
        v_in = np.where((v[group] >= v_lo) & (v[group] <= v_hi), v[group], (v_lo + v_hi) / 2)
        out.append((suffix, weight, s_in, v_in, [lo, hi, v_lo, v_hi]))
    return out
