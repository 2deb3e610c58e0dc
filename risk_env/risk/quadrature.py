"""The fixed quadrature rule of the exact risk's disc probability.

Shared by the generic form (:func:`risk_env.risk.disc.disc_probability`, numpy and CasADi) and the
numpy kernels (:mod:`risk_env.risk.exact_kernel`), so both integrate on the same nodes. The MPC's
constraint uses the same rule cut at +-5 sigma (``SOLVER_*``), with its bounded shortfall added.

The rule is exact to 1e-5 for beliefs of any aspect ratio (``python -m benchmarks.exact_accuracy``,
against nested adaptive quadrature): which axis is integrated by quadrature (the outer one) and
where its segments end are chosen per belief and ego state (:func:`risk_env.risk.disc.disc_probability`).
"""

from __future__ import annotations

import math

import numpy as np

GAUSS_NODES = 6
"""Gauss-Legendre nodes per quadrature segment of the disc probability."""
GAUSS_X, GAUSS_W = np.polynomial.legendre.leggauss(GAUSS_NODES)
"""Nodes on [-1, 1] and their weights, ``(GAUSS_NODES,)`` each."""
SIGMA_BREAKS = (-5.0, -2.5, -1.0, 1.0, 2.5, 5.0)
"""Where (in standard deviations of the outer axis) the quadrature splits."""
SEGMENTS = len(SIGMA_BREAKS) + 5
"""Segments of the outer integral: between the range's two ends, the sigma breaks and the four
angles where the chord's ends cross the inner box edges."""
EDGE = 1.0 - 1e-12
"""Arguments of asin / acos are clipped to this, keeping their derivatives finite."""
SUPPORT = 7.0
"""The rule covers at most +-SUPPORT standard deviations of either axis (the mass beyond: < 3e-12
per axis): the outer quadrature's range, and the inner axis' reach, to which the outer range is cut
(where the chord comes no nearer to the inner mean, P gets nothing: otherwise P there would be
the rounding of two near-equal terms of the complementary form, ~1e-8). P is exactly 0 where the
disc misses the box cut to +-SUPPORT sigma (:func:`~risk_env.risk.disc.support_halves`)."""
GEOMETRY_FLOOR = 1e-6
"""Standard deviations and box half widths [m] below this are raised to it: a point mass is
represented to within 1e-6 m."""

SOLVER_SIGMA_BREAKS = (-2.5, -1.0, 1.0, 2.5)
"""The MPC's rule (:meth:`risk_env.risk.estimators.ExactRisk.casadi_margin`): the env's breaks but +-5 sigma,
where its outer integral ends (:data:`SOLVER_SUPPORT`)."""
SOLVER_SUPPORT = 5.0
"""The MPC's rule covers at most +-5 standard deviations of the outer axis (the inner axis' reach
stays :data:`SUPPORT`): two of the env's eleven
segments fewer (54 nodes, not 66), the others the same."""
SOLVER_SHORTFALL = math.erfc(SOLVER_SUPPORT / math.sqrt(2.0)) / math.erf(SOLVER_SUPPORT / math.sqrt(2.0))
"""Bound on how far the MPC's P falls below the env's (5.7e-7): the truncated outer mass beyond
+-5 sigma, ``2 (1 - Phi(5)) / Z_x``, which the env's rule integrates and the MPC's does not (the
cut binds only where the box reaches past 5 sigma, so Z_x >= erf(5 / sqrt 2)); the rest of the two
rules is the same segments and nodes. The MPC adds it back to stay conservative."""
