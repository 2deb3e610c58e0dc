"""The lane predictor's modes: :class:`LaneMode`, a route mode's parts, whole or held and
free (:class:`~risk_env.highway.lanes.interval.IntervalBounds`), and a road user's mixture of them
(:func:`lane_mixture`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from risk_env.highway.lanes.beliefs import Stretch, mode_beliefs
from risk_env.highway.lanes.hypotheses import Hypotheses
from risk_env.highway.lanes.interval import IntervalBounds
from risk_env.prediction.mixture import Mixture, Mode

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


def lane_mixture(
    predictor: Any,
    row: np.ndarray,
    hyp: Hypotheses,
    s: np.ndarray,
    v: np.ndarray,
    bounds: IntervalBounds | None,
) -> Mixture:
    """The mixture of one road user of the lane predictor ``predictor``
    (:class:`~risk_env.highway.lanes.predictor.LanePredictor`, whose numbers it reads): its
    modes from its routes' arc lengths and speeds ``(R, N+1)`` (and their interval bounds,
    :func:`~risk_env.highway.lanes.interval.interval_bounds`, or None)."""
    modes = []
    iv = predictor.intervals
    drift = (iv.drift_rate, iv.drift_cap) if bounds is not None and iv.reversing else None
    for group, label in zip(hyp.groups, hyp.labels, strict=True):
        w = hyp.weights[group]
        total = float(w.sum())
        lead = group[int(np.argmax(w))]
        share = w / total if total > 0 else np.full(len(group), 1.0 / len(group))
        for suffix, part, s_b, v_b, box in mode_parts(group, share, s, v, bounds):
            routes = tuple(
                (hyp.routes[k].label(), float(hyp.weights[k]) * part / predictor.pieces) for k in group
            )
            for j in range(predictor.pieces):
                beliefs, stretch = mode_beliefs(
                    predictor.spread,
                    hyp.routes[lead],
                    s_b,
                    v_b,
                    share,
                    float(hyp.starts[lead]),
                    float(hyp.offsets[lead]),
                    float(row[3]),
                    predictor.dt,
                    predictor.traffic.max_acceleration,
                    predictor.traffic.lateral_time,
                    (j, predictor.pieces),
                    box,
                    0.0 if bounds is None else predictor.intervals.margin_turn,
                    predictor.intervals.centred,
                    predictor.intervals.fitted,
                    drift,
                )
                name = label + suffix + ("" if predictor.pieces == 1 else f"#{j + 1}/{predictor.pieces}")
                modes.append((total * part / predictor.pieces, beliefs, name, routes, stretch))
    norm = sum(m[0] for m in modes)
    share = 1.0 / predictor.pieces
    return Mixture(
        tuple(LaneMode(w / norm, b, label, share, routes=r, stretch=st) for w, b, label, r, st in modes)
    )
