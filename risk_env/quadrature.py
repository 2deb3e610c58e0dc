"""The fixed quadrature rule of the exact risk's disc probability.

Shared by the generic form (:func:`risk_env.risk.disc_probability`, numpy and CasADi) and the
numpy kernels (:mod:`risk_env.exact_kernel`), so both integrate on the same nodes.
"""

from __future__ import annotations

import numpy as np

GAUSS_NODES = 4
"""Gauss-Legendre nodes per quadrature segment of the disc probability."""
GAUSS_X, GAUSS_W = np.polynomial.legendre.leggauss(GAUSS_NODES)
"""Nodes on [-1, 1] and their weights, ``(GAUSS_NODES,)`` each."""
SIGMA_BREAKS = (-5.0, -2.5, -1.0, 0.0, 1.0, 2.5, 5.0)
"""Where (in standard deviations of the outer axis) the quadrature splits."""
SEGMENTS = len(SIGMA_BREAKS) + 5
"""Segments of the outer integral: between the range's two ends, the sigma breaks and the four
angles where the chord's ends cross the inner box edges."""
EDGE = 1.0 - 1e-12
"""Arguments of asin / acos are clipped to this, keeping their derivatives finite."""
SUPPORT = 7.0
"""The outer quadrature covers at most +-SUPPORT standard deviations (mass beyond: < 3e-12)."""
GEOMETRY_FLOOR = 1e-6
"""Standard deviations and box half widths [m] below this are raised to it: a point mass is
represented to within 1e-6 m."""
