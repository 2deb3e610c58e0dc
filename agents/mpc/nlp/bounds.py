"""The bounds of the NLP's variables (:mod:`agents.mpc.nlp.ocp`) at a step: the measured start, the
input bounds, the path's start and the slacks' sign."""

from __future__ import annotations

import numpy as np

from risk_env.scenario.scenario import Scenario


def variable_bounds(
    scenario: Scenario,
    x_index: np.ndarray,
    u_index: np.ndarray,
    n_w: int,
    x0: np.ndarray,
    slack_index: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    r"""``(lbx, ubx)`` of w ``(n_w,)``: $x_0$ fixed to the measurement, $\lambda_n \ge$ the path's
    start, the input bounds, slacks (at ``slack_index``) $\ge 0$."""
    ego = scenario.ego
    lbx, ubx = np.full(n_w, -np.inf), np.full(n_w, np.inf)
    if slack_index is not None:
        lbx[slack_index] = 0.0
    lbx[x_index[0]] = ubx[x_index[0]] = x0
    lbx[x_index[1:, 3]] = min(scenario.path.lambda_start, x0[3])
    lbx[u_index] = (ego.v_min, -ego.omega_max, ego.v_min)
    ubx[u_index] = (ego.v_max, ego.omega_max, ego.v_max)
    return lbx, ubx
