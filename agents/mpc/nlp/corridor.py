r"""The path's corridor in the NLP: the planned ego centre keeps within $\pm c$ of the arc
($c$ = ``path.corridor`` [m], none when infinite), at the states $n = 1, \dots, N$.

- **Hard variants**: one row per stage, $-c \le d_n \le c$, $d_n$ the lateral offset of state $n$
  (:func:`risk_env.models.path.lateral_offset`).
- **Soft variants** (wherever the risk rows are soft, :mod:`agents.mpc.nlp.ocp`): the corridor is
  softened by the same mechanism, a slack $\sigma_n \ge 0$ [m] per stage (a control of stage $n$, tagged
  ``(n, "s", 2)``) in two rows, $d_n + \sigma_n \ge -c$ and $d_n - \sigma_n \le c$, with
  $\rho\, w_c\, \sigma_n$ added to the objective (:func:`corridor_weight`: $w_c = q^N$ at every stage, so a
  metre outside the corridor costs more than a margin unit of the risk rows at any stage, whose
  slacks cost at most $2 \rho q^{N-1}$). An exact L1 penalty as the risk rows': where the hard
  problem (risk rows and corridor) is feasible, the soft one's solution is the hard one's, with zero
  slacks. Where it is not (a prediction's box covers the lane and the ego cannot stop short of
  it), the soft plan keeps to its lane and enters the box the least it can, rather than leaving the
  road; it leaves the corridor only where no plan keeps it. Before, the corridor stayed hard in the
  soft variants (every initial point off the corridor started infeasible), and when the soft
  problem failed the fallback's manoeuvres, which knew no corridor, left the road
  (:mod:`agents.mpc.fallback` now ranks by it).

A step sets the bound $c$ (widened for an ego that starts outside it: :func:`step_widths`) on the
finite side of each row; the rows' infinite sides stay,
so the split into equalities and inequalities every call keeps does not change
(:mod:`agents.mpc.nlp.calls`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from risk_env.models.path import lateral_offset, point, project

CORRIDOR_WEIGHT = 1.0
r"""A corridor slack of 1 m at any stage costs this many times $\rho\, q^N$ (:func:`corridor_weight`)."""


def corridor_weight(N: int, q: float) -> float:
    r"""The cost of a corridor slack of 1 m at any stage over $\rho$: :data:`CORRIDOR_WEIGHT` $q^N$
    ($q$: the risk slacks' early weight, :data:`agents.mpc.nlp.ocp.EARLY_WEIGHT`), more than a risk
    slack of one margin unit costs at any stage (at most $(1 + $ ``NEAR_WEIGHT`` $)\, q^{N-1}$)."""
    return CORRIDOR_WEIGHT * q**N


CORRIDOR_SLACK = 2
"""The component of a corridor slack's tag ``(n, "s", 2)`` (0: the risk rows', 1: the budget's)."""


def corridor_rows(offset: Any, width: float, slack: Any = None) -> list[tuple[Any, float, float]]:
    """``(row, lower, upper)`` of one stage: the lateral ``offset`` [m] within ``width`` [m]; with a
    ``slack`` (a soft variant) the two one-sided rows softened by it."""
    if slack is None:
        return [(offset, -width, width)]
    return [(offset + slack, -width, math.inf), (offset - slack, -math.inf, width)]


def step_bounds(
    nominal_lbg: np.ndarray, nominal_ubg: np.ndarray, width: float
) -> tuple[np.ndarray, np.ndarray]:
    """The corridor rows' bounds at a step's half ``width`` [m] (a number or one per row): on each
    row's finite sides."""
    lower = np.where(np.isfinite(nominal_lbg), -width, -np.inf)
    upper = np.where(np.isfinite(nominal_ubg), width, np.inf)
    return lower, upper


def step_widths(
    scenario: Any, x: float, y: float, soft: bool, free: bool, reentry: float, theta: float = 0.0
) -> np.ndarray:
    r"""The corridor's half widths [m] at $n = 1, \dots, N$ for an ego at ``(x, y)`` [m] heading
    ``theta`` [rad]: the path's; for an ego that starts outside it, in a hard variant, its offset plus
    ``reentry`` (so that the start alone never makes the problem infeasible), narrowing to the path's
    at $n = N$ where there are risk rows (a constant widening let each plan edge further out: at the
    intersection the lanes' boxes pushed the ego off the road half a metre a step), constant in the
    ``free`` problem (which has no soft variant). A ``soft`` variant keeps the path's: its slacks pay
    for the start. An ego with a curvature limit (:attr:`~risk_env.scenario.parts.Ego.curvature_max`)
    heading outwards first drifts out by :func:`turn_back` before it can turn back: that counts as
    part of its offset, in the soft variants too (no slack can pay for what no plan avoids), and the
    corridor narrows to its offset now, not to the path's: back, never further out (in the ``free``
    problem too, whose constant widening let the ego edge out at every step)."""
    path, N = scenario.path, scenario.horizon
    signed = float(lateral_offset(path, x, y))
    drift = turn_back(scenario, signed, x, y, theta)
    offset = abs(signed) + drift
    if offset <= path.corridor or (soft and drift == 0.0):
        return np.full(N, path.corridor)
    wide = offset + reentry
    if free and drift == 0.0:
        return np.full(N, wide)
    floor = max(path.corridor, abs(signed)) if drift > 0.0 else path.corridor  # never further out
    return floor + (wide - floor) * (1.0 - np.arange(1, N + 1) / N)


def turn_back(scenario: Any, offset: float, x: float, y: float, theta: float) -> float:
    r"""How far [m] further out an ego at ``(x, y)`` [m] with lateral ``offset`` [m] drifts while it
    turns parallel to the path from heading ``theta`` [rad] at its tightest, $R (1 - \cos \Delta)$ with
    $R = 1 / \kappa_{max}$ and $\Delta$ its heading's angle away from the path, when it heads outwards;
    0 when it heads inwards or turns standing (no curvature limit)."""
    kappa = scenario.ego.curvature_max
    if not math.isfinite(kappa):
        return 0.0
    _, _, heading = point(scenario.path, project(scenario.path, x, y))
    delta = math.remainder(theta - float(heading), 2.0 * math.pi)
    if offset * math.sin(delta) <= 0.0:  # inwards, or along the path
        return 0.0
    return (1.0 - math.cos(min(abs(delta), math.pi / 2))) / kappa


def fill_slacks(problem: Any, w: np.ndarray, g: np.ndarray, lbg: np.ndarray, push: float) -> np.ndarray:
    """Set a soft variant's corridor slacks in ``w`` (in place) to how far each stage's state lies
    outside the corridor of the step's bounds ``lbg`` (plus ``push``), and the rows ``g`` (in place)
    to what they are then; returns the upper bounds of the rows at the step's corridor."""
    ubg = problem.ubg.copy()
    rows = problem.corridor_rows
    if not problem.corridor_slack.size:  # none, or hard: one row per stage within -lbg and lbg
        ubg[rows] = -lbg[rows]
        return ubg
    lower = np.isfinite(problem.lbg[rows])  # each stage: the lower row, then the upper one
    width = -lbg[rows[lower]]
    ubg[rows[~lower]] = width
    offset = g[rows[lower]] - w[problem.slack_index[problem.corridor_slack[lower]]]
    sigma = np.maximum(np.abs(offset) - width, 0.0) + push
    w[problem.slack_index[problem.corridor_slack[lower]]] = sigma
    g[rows[lower]] = offset + sigma
    g[rows[~lower]] = offset - sigma
    return ubg
