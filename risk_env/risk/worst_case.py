"""The worst-case risk (paper eq. 17), :class:`WorstCaseRisk`: the maximum of $I_C s$ over the
truncation box (in the belief's frame) and the speed interval, exactly or on the paper's grid."""

from __future__ import annotations

from typing import Any

import casadi as ca

from risk_env.models.frame import to_frame
from risk_env.models.ops import CASADI, MATH, NUMPY, Ops
from risk_env.prediction.belief import Belief
from risk_env.risk.disc import signed_box_distance
from risk_env.risk.estimator import RiskEstimator, ego_parts
from risk_env.risk.quadrature import GEOMETRY_FLOOR
from risk_env.scenario.scenario import Scenario


def box_distance(ego: Any, belief: Belief, ops: Ops = NUMPY) -> Any:
    """Signed distance [m] from the ego centre to the belief's truncation box, in its frame
    (negative inside)."""
    x, y, _, _ = ego_parts(ego)
    dx, dy = to_frame(x - belief.x, y - belief.y, belief.frame, ops)
    return signed_box_distance(dx, dy, belief.half_x, belief.half_y, ops)


class WorstCaseRisk(RiskEstimator):
    r"""$\max I_C s$ over the truncation box and speed interval (paper eq. 17); the box and its grid
    lie in the belief's frame.

    Exact box form (default): $1[\text{signed distance to the box} \le r]$ times the worst severity
    over the speed interval. ``grid=True``: the paper's under-approximation on $L$ points per
    interval ($L$ = ``scenario.grid_points``), evaluated through the nearest grid point per axis,
    which equals the brute-force maximum over the $L^3$ grid.
    """

    smooth = False

    def __init__(self, scenario: Scenario, grid: bool = False, grid_points: int | None = None) -> None:
        super().__init__(scenario)
        self.grid = grid
        self.grid_points = scenario.grid_points if grid_points is None else int(grid_points)
        if self.grid_points < 2:
            raise ValueError(f"grid_points must be >= 2, got {grid_points}")
        self.name = "grid" if grid else "worst_case"

    def _snap(self, d: Any, half: Any, ops: Ops) -> Any:
        """The grid point of ``[-half, half]`` (L points) nearest to ``d``."""
        h = ops.maximum(half, GEOMETRY_FLOOR)
        spacing = 2.0 * h / (self.grid_points - 1)
        return -h + spacing * ops.floor((ops.clip(d, -h, h) + h) / spacing + 0.5)

    def distance(self, ego: Any, belief: Belief, ops: Ops = NUMPY) -> Any:
        """Distance [m] from the ego centre to the nearest possible object centre (signed for
        the box: negative inside). The box and the grid lie in the belief's frame: the offset is
        turned into it (distances do not change)."""
        if not self.grid:
            return box_distance(ego, belief, ops)
        x, y, _, _ = ego_parts(ego)
        dx, dy = to_frame(x - belief.x, y - belief.y, belief.frame, ops)
        ex = dx - self._snap(dx, belief.half_x, ops)
        ey = dy - self._snap(dy, belief.half_y, ops)
        return ops.sqrt(ex * ex + ey * ey + 1e-12) - 1e-6

    def worst_severity(self, ego: Any, belief: Belief, ops: Ops = NUMPY) -> Any:
        """max of s over the speed interval (or its L grid points)."""
        _, _, th, v = ego_parts(ego)
        lo, hi = belief.v_lo, belief.v_hi
        near0 = ops.clip(0.0 * v, lo, hi)
        if self.grid:
            mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
            near0 = mid + self._snap(near0 - mid, half, ops)
        return self.severity.worst(v, th, lo, hi, near0, belief.theta, ops)

    def _risk(self, ego, belief, ops, **kwargs):
        hit = self.distance(ego, belief, ops) <= self.radius
        s = self.worst_severity(ego, belief, ops)
        return ops.where(hit, s, 0.0 * s)

    def risk_one(self, ego, belief, rng=None):
        """As :meth:`RiskEstimator.risk_one`: the same formulas on the MATH face."""
        return float(self._risk(ego, belief, MATH))

    def casadi_margin(self, ego, belief, epsilon, **kwargs):
        r"""$\max(d - r, (\epsilon - s_{worst}) / \mathrm{scale}) \ge 0$, $d$ the distance [m]: keep the
        ego disc off
        every possible object position, unless even the worst severity is tolerable."""
        clearance = self.distance(ego, belief, CASADI) - self.radius
        slack = (epsilon - self.worst_severity(ego, belief, CASADI)) / self.severity.scale
        return ca.fmax(clearance, slack)
