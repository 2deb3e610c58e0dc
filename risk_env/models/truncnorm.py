"""Truncated normal distributions: sampling (numpy) and partial moments (both backends)."""

from __future__ import annotations

from typing import Any

import numpy as np

from risk_env.models.ops import NUMPY, Ops

SIGMA_FLOOR = 1e-9
"""Standard deviations below this [units of the variable] are treated as a point mass."""


def sample(
    mean: np.ndarray,
    sigma: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    rng: np.random.Generator,
    size: tuple[int, ...] = (),
) -> np.ndarray:
    r"""Draws of $N(\mu, \sigma^2)$ (``mean``, ``sigma``) truncated to ``[lo, hi]``, shape ``size +
    broadcast shape``.

    Inverse-CDF sampling, done on the side of the mean where the tail is thin so that far tails
    keep their precision. A zero ``sigma`` or a zero-width interval gives the clipped mean.
    """
    shape = tuple(size) + np.broadcast_shapes(*(np.shape(a) for a in (mean, sigma, lo, hi)))
    return transform(rng.random(shape), mean, sigma, lo, hi)


def transform(u: Any, mean: Any, sigma: Any, lo: Any, hi: Any, ops: Ops = NUMPY) -> Any:
    """The inverse-CDF map of :func:`sample`: uniforms ``u`` on [0, 1) to truncated-normal draws
    (numpy: the shape of ``u`` broadcast with the parameters; or Python floats)."""
    degenerate = (sigma <= SIGMA_FLOOR) | (hi <= lo)
    s = ops.where(degenerate, 1.0, sigma)
    a = (lo - mean) / s
    b = (hi - mean) / s
    flip = a > 0  # both bounds above the mean: sample the mirrored lower tail instead
    a2 = ops.where(flip, -b, a)
    b2 = ops.where(flip, -a, b)
    pa, pb = ops.norm_cdf(a2), ops.norm_cdf(b2)
    z = ops.norm_ppf(pa + u * (pb - pa))
    z = ops.where(flip, -z, z)
    draws = ops.clip(mean + s * z, lo, hi)
    return ops.where(degenerate, ops.clip(mean, lo, hi), draws)


def partial_moments(
    mu: Any, sigma: Any, lo: Any, hi: Any, left: Any, right: Any, ops: Ops
) -> tuple[Any, Any, Any]:
    r"""Probability, first and second moment of $X \sim N(\mu, \sigma^2)$ truncated to ``[lo, hi]``,
    restricted to $I$ = ``[left, right]``: $(P(X \in I),\, E[X\, 1\{X \in I\}],\, E[X^2\, 1\{X \in I\}])$.

    ``sigma`` must be positive; callers floor it.
    """
    a = (ops.clip(left, lo, hi) - mu) / sigma
    b = (ops.clip(right, lo, hi) - mu) / sigma
    b = ops.maximum(a, b)
    za = ops.norm_cdf((lo - mu) / sigma)
    zb = ops.norm_cdf((hi - mu) / sigma)
    norm = ops.maximum(zb - za, 1e-300)
    pa, pb = ops.norm_pdf(a), ops.norm_pdf(b)
    p = ops.norm_cdf(b) - ops.norm_cdf(a)
    m1 = mu * p + sigma * (pa - pb)
    m2 = (mu * mu + sigma * sigma) * p + 2.0 * mu * sigma * (pa - pb) + sigma * sigma * (a * pa - b * pb)
    return p / norm, m1 / norm, m2 / norm
