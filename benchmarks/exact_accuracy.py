"""How exact is the exact risk? Its disc probability against nested adaptive quadrature, on random
beliefs of any aspect ratio and rotation.

    python -m benchmarks.exact_accuracy --beliefs 1000
    python -m benchmarks.exact_accuracy --beliefs 10000 --seed 0 --out docs/results/exact_accuracy.txt

Each belief is drawn in its own frame: the larger standard deviation log-uniform in [0.01, 30] m,
the aspect ratio 1 (a sixth of them) or log-uniform up to 1:1000 (either axis the long one), box
half widths 0.05 to 15 standard deviations (a tenth untruncated), a random frame angle. The ego
offset is one of four kinds in turn: anywhere the disc may meet the box, the disc's edge through
a likely point of the belief, the disc's edge near a box corner, the mean inside the disc. The
collision distance is the scenario's r = 3 m; with the severity ``probability`` R is P.

The reference (:func:`reference_probability`) integrates the truncated density over the disc in
the belief's frame, from the generated offset (not the estimator's rotation): scipy's adaptive
``quad`` over one axis, the other in closed form with Phi, split at the box edges, at multiples
of both axes' standard deviations and where the chord's ends cross them. Integrated in both
orders; their largest disagreement is printed as the reference's own accuracy.

Printed per path of the estimator (the env's numpy batch and scalar kernels, the generic numpy
form, the SMPC's CasADi form :meth:`~risk_env.risk.estimators.ExactRisk.solver_risk`): the largest absolute
error, the largest shortfall below the reference (the unsafe side) and how many fall short by more
than 1e-5. Targets: at most 1e-4 absolute, never short by more than 1e-5.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import casadi as ca
import numpy as np
from scipy import integrate

from benchmarks import cli
from risk_env import Belief, Scenario
from risk_env.models.frame import from_frame
from risk_env.risk import ExactRisk
from risk_env.risk.disc import disc_probability, signed_box_distance

RADIUS = Scenario().collision_distance
"""r = r_e + r_o [m]: the scenario's."""
ABS_TARGET = 1e-4
"""Largest absolute error of P allowed."""
SHORT_TARGET = 1e-5
"""Largest shortfall of P below the reference allowed (the unsafe side)."""
_LEVELS = (-8.0, -5.0, -3.0, -2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0)


def random_beliefs(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """``n`` random geometries whose disc (radius :data:`RADIUS`) meets the box: arrays ``(n,)``
    of the offset in the belief's frame ``along, across`` [m], ``sx, sy, hx, hy`` [m], ``frame``
    [rad] and the world offset ``dx, dy`` [m] (ego centre minus mean)."""
    r = RADIUS
    rows = []
    while len(rows) < n:
        big = math.exp(rng.uniform(math.log(0.01), math.log(30.0)))
        ratio = 1.0 if rng.random() < 1 / 6 else math.exp(rng.uniform(0.0, math.log(1000.0)))
        s = np.array([big, big / ratio])[:: 1 if rng.random() < 0.5 else -1]
        h = s * (1e3 if rng.random() < 0.1 else np.exp(rng.uniform(math.log(0.05), math.log(15.0), 2)))
        kind = len(rows) % 4
        angle = rng.uniform(0.0, 2.0 * math.pi)
        e = np.array([math.cos(angle), math.sin(angle)])
        if kind == 0:  # anywhere the disc may meet the box
            d = rng.uniform(-1.0, 1.0, 2) * (h + r)
        elif kind == 1:  # the disc's edge through a likely point
            p = np.clip(rng.normal(0.0, 1.0, 2) * s, -h, h)
            d = p + (r + rng.normal() * min(3.0 * s.min(), r)) * e
        elif kind == 2:  # the disc's edge near a box corner or edge
            d = np.clip(e * 1e9, -h, h) + e * r * rng.uniform(0.9, 1.1) + rng.normal(0.0, 1.0, 2) * s
        else:  # the mean inside the disc
            d = rng.uniform(0.0, 1.0) * r * e
        if signed_box_distance(d[0], d[1], h[0], h[1]) < r:
            rows.append((d[0], d[1], *s, *h, rng.uniform(-math.pi, math.pi)))
    a = np.array(rows).T
    out = dict(zip(("along", "across", "sx", "sy", "hx", "hy", "frame"), a))
    out["dx"], out["dy"] = from_frame(out["along"], out["across"], out["frame"])
    return out


def _order(dx: float, dy: float, r: float, sx: float, sy: float, hx: float, hy: float) -> float:
    """P by adaptive quadrature over x (outer), y in closed form; offsets in the belief's frame."""
    lo, hi = max(-hx, dx - r), min(hx, dx + r)
    if hi <= lo:
        return 0.0
    zx, zy = math.erf(hx / (sx * math.sqrt(2.0))), math.erf(hy / (sy * math.sqrt(2.0)))

    def phi_cdf(z: float) -> float:
        return 0.5 * math.erfc(-z / math.sqrt(2.0))

    def inner(x: float) -> float:
        c = math.sqrt(max(r * r - (x - dx) ** 2, 0.0))
        a, b = max(-hy, dy - c), min(hy, dy + c)
        if b <= a:
            return 0.0
        density = math.exp(-0.5 * (x / sx) ** 2) / (sx * math.sqrt(2.0 * math.pi))
        return density * (phi_cdf(b / sy) - phi_cdf(a / sy))

    points = [k * sx for k in _LEVELS]
    for level in (hy, -hy, *(k * sy for k in _LEVELS)):  # chord ends crossing these levels
        c = abs(level - dy)
        if c < r:
            w = math.sqrt(r * r - c * c)
            points += [dx - w, dx + w]
    edges = [lo, *sorted(p for p in set(points) if lo < p < hi), hi]
    total = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        total += integrate.quad(inner, a, b, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
    return total / (zx * zy)


def reference_probability(
    dx: float, dy: float, r: float, sx: float, sy: float, hx: float, hy: float
) -> tuple[float, float]:
    """P(||d - z|| <= r) for z ~ N(0, diag(sx^2, sy^2)) truncated to ``[-hx, hx] x [-hy, hy]``,
    ``(dx, dy)`` in the belief's frame [m], by nested adaptive quadrature in both orders:
    ``(P, disagreement of the two orders)`` (P from the order whose outer axis is the narrower)."""
    a = _order(dx, dy, r, sx, sy, hx, hy)
    b = _order(dy, dx, r, sy, sx, hy, hx)
    return (a if sx <= sy else b), abs(a - b)


def references(cases: dict[str, np.ndarray]) -> np.ndarray:
    """:func:`reference_probability` at every case: ``(n, 2)``, P and the orders' disagreement."""
    keys = ("along", "across", "sx", "sy", "hx", "hy")
    rows = zip(*(cases[k].tolist() for k in keys))
    return np.array([reference_probability(a, c, RADIUS, sx, sy, hx, hy) for a, c, sx, sy, hx, hy in rows])


def estimates(cases: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """P at every case by each path of the exact risk, from the world offsets and the frames."""
    n = len(cases["dx"])
    est = ExactRisk(Scenario(severity="probability"))
    belief = Belief(
        0.0, 0.0, 0.0, 0.0, cases["sx"], cases["sy"], 1.0, cases["hx"], cases["hy"], -5.0, 5.0, cases["frame"]
    )
    ego = np.column_stack([cases["dx"], cases["dy"], np.zeros(n), np.zeros(n)])
    rows = belief.as_array().tolist()  # one belief of Python floats per case: the env's scalar path
    scalar = np.array([est.risk_one(tuple(e), Belief(*row)) for e, row in zip(ego.tolist(), rows)])
    e, p = ca.SX.sym("e", 4), ca.SX.sym("p", Belief.SIZE)
    solver = ca.Function("solver", [e, p], [est.solver_risk(e, Belief.from_array(p))])
    return {
        "env, numpy batch": est.risk(ego, belief),
        "env, numpy scalar": scalar,
        "generic form (numpy face)": np.asarray(disc_probability(cases["dx"], cases["dy"], RADIUS, belief)),
        "SMPC's CasADi form": np.array(solver.map(n)(ego.T, belief.as_array().T)).ravel(),
    }


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.exact_accuracy``."""
    parser = cli.parser("exact_accuracy", __doc__)
    parser.add_argument("--beliefs", type=cli.positive_int, default=10_000, help="random beliefs")
    parser.add_argument("--seed", type=cli.nonnegative_int, default=0, help="seed of the random beliefs")
    parser.add_argument(
        "--out", type=Path, default=None, help="also write the report to this file (default: print only)"
    )
    return parser


def main(argv: list[str] | None = None) -> dict[str, tuple[float, float, int]]:
    args = build_parser().parse_args(argv)
    cases = random_beliefs(np.random.default_rng(args.seed), args.beliefs)
    ref = references(cases)
    lines = [
        f"{args.beliefs} random beliefs (seed {args.seed}), r = {RADIUS:g} m; reference: nested adaptive"
        f" quadrature, its two orders agree to {ref[:, 1].max():.1e}",
        f"{'path':28s}  {'max |error|':>11s}  {'max below':>9s}  {'below 1e-5':>10s}",
    ]
    results = {}
    for name, got in estimates(cases).items():
        err = got - ref[:, 0]
        worst, short = float(np.abs(err).max()), float(max(-err.min(), 0.0))
        count = int(np.sum(err < -SHORT_TARGET))
        results[name] = (worst, short, count)
        lines.append(f"{name:28s}  {worst:11.1e}  {short:9.1e}  {count:10d}")
    met = all(w <= ABS_TARGET and c == 0 for w, _, c in results.values())
    verdict = "met" if met else "NOT met"
    lines.append(f"targets (|error| <= {ABS_TARGET:g}, never below by more than {SHORT_TARGET:g}): {verdict}")
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    return results


if __name__ == "__main__":
    main()
