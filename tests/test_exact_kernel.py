"""The numpy kernels of the exact risk equal the generic (Ops) form, which the MPC's CasADi
constraints share: same nodes, same maths, differences at rounding level."""

import numpy as np
import pytest
from scipy import special

from risk_env import Belief, Scenario, make_estimator, predict_array
from risk_env.models.ops import MATH, NUMPY
from risk_env.risk.estimators import GEOMETRY_FLOOR, disc_probability, signed_box_distance
from risk_env.risk.exact_kernel import (
    _PHI_LIM,
    _PHI_OFFSET,
    _PHI_STEP,
    _phi_table,
    disc_probability_batch,
    disc_probability_scalar,
)
from risk_env.scenario.scenario import SEVERITY_NAMES

P_TOL = 1e-12
"""Absolute tolerance on P (in [0, 1]) between the kernels and the generic form."""


def random_cases(
    rng: np.random.Generator, beliefs: int, states: int, radius: float | None = None
) -> list[tuple]:
    """(dx, dy, r, sx, sy, hx, hy) with ``states`` offsets whose disc meets the box, per belief:
    sigma 0.01-3 m, box half widths 0.05-12 sigma (truncation active or not), radius 1-5 m
    (unless given), a third of them isotropic; offsets up to the disc's reach beyond the box."""
    cases = []
    for i in range(beliefs):
        sx, sy = rng.uniform(0.01, 3.0, 2)
        hx, hy = np.array([sx, sy]) * np.exp(rng.uniform(np.log(0.05), np.log(12.0), 2))
        if i % 3 == 0:
            sy, hy = sx, hx
        r = rng.uniform(1.0, 5.0) if radius is None else radius
        dx = rng.uniform(-1, 1, 4 * states) * (hx + r)
        dy = rng.uniform(-1, 1, 4 * states) * (hy + r)
        near = signed_box_distance(dx, dy, hx, hy) < r
        cases.append((dx[near][:states], dy[near][:states], r, sx, sy, hx, hy))
    return cases


def generic(dx, dy, r, sx, sy, hx, hy):
    return disc_probability(dx, dy, r, Belief(0.0, 0.0, 0.0, 0.0, sx, sy, 1.0, hx, hy, -5.0, 5.0), gate=False)


def test_cases_cover_the_geometries():
    cases = random_cases(np.random.default_rng(0), 200, 200)
    dx = np.concatenate([c[0] for c in cases])
    dy = np.concatenate([c[1] for c in cases])
    hx = np.concatenate([np.full(len(c[0]), c[5]) for c in cases])
    hy = np.concatenate([np.full(len(c[0]), c[6]) for c in cases])
    gap = signed_box_distance(dx, dy, hx, hy)
    assert np.mean(gap < 0) > 0.05  # ego centre inside the box: overlapping
    assert 0.3 < np.mean(np.abs(dx) > np.abs(dy)) < 0.7  # either axis is the outer one
    assert np.mean([c[5] < 2 * c[3] or c[6] < 2 * c[4] for c in cases]) > 0.2  # truncation active
    assert np.mean([c[5] > 4 * c[3] and c[6] > 4 * c[4] for c in cases]) > 0.05  # barely truncated


def test_batch_kernel_equals_generic_form():
    worst = 0.0
    for dx, dy, r, sx, sy, hx, hy in random_cases(np.random.default_rng(1), 200, 200):
        ref = generic(dx, dy, r, sx, sy, hx, hy)
        shared = disc_probability_batch(dx, dy, r, sx, sy, hx, hy)  # one belief for all states
        each = disc_probability_batch(dx, dy, r, *(np.full(len(dx), v) for v in (sx, sy, hx, hy)))
        worst = max(worst, np.abs(shared - ref).max(), np.abs(each - ref).max())
    assert worst <= P_TOL


def test_batch_kernel_with_a_belief_per_state():
    cases = random_cases(np.random.default_rng(2), 300, 3, radius=3.0)
    dx, dy = (np.concatenate([c[k] for c in cases]) for k in (0, 1))
    sx, sy, hx, hy = (np.concatenate([np.full(len(c[0]), c[k]) for c in cases]) for k in range(3, 7))
    ref = np.concatenate([generic(*c) for c in cases])
    assert np.abs(disc_probability_batch(dx, dy, 3.0, sx, sy, hx, hy) - ref).max() <= P_TOL


def test_scalar_kernel_equals_generic_form():
    worst = 0.0
    for dx, dy, r, sx, sy, hx, hy in random_cases(np.random.default_rng(3), 60, 40):
        ref = generic(dx, dy, r, sx, sy, hx, hy)
        got = np.array([disc_probability_scalar(a, b, r, sx, sy, hx, hy) for a, b in zip(dx, dy)])
        worst = max(worst, np.abs(got - ref).max())
    assert worst <= P_TOL


@pytest.mark.parametrize("degenerate", ["point mass", "no spread", "no box"])
def test_kernels_on_floored_beliefs(degenerate):
    """At the geometry floor the generic form itself is ill-conditioned (P = (mass zy - missed)
    / (zx zy) with zx zy ~ 1e-12): the kernels still agree with it to 1e-8."""
    rng = np.random.default_rng(4)
    sx, sy, hx, hy = {
        "point mass": (0.0, 0.0, 0.0, 0.0),
        "no spread": (0.0, 0.0, 1.0, 0.5),
        "no box": (1.2, 0.7, 0.0, 0.0),
    }[degenerate]
    f = [max(v, GEOMETRY_FLOOR) for v in (sx, sy, hx, hy)]
    dx, dy = rng.uniform(-4, 4, (2, 400))
    near = signed_box_distance(dx, dy, f[2], f[3]) < 3.0
    dx, dy = dx[near], dy[near]
    ref = generic(dx, dy, 3.0, sx, sy, hx, hy)
    got = disc_probability_batch(dx, dy, 3.0, *f)
    one = np.array([disc_probability_scalar(a, b, 3.0, *f) for a, b in zip(dx, dy)])
    assert np.all(np.isfinite(got)) and np.all((got >= 0) & (got <= 1))
    np.testing.assert_allclose(got, ref, atol=1e-8)
    np.testing.assert_allclose(one, ref, atol=1e-8)


def test_phi_table_matches_ndtr():
    z = np.linspace(-_PHI_LIM - 1.0, _PHI_LIM + 1.0, 400_001)
    got = _phi_table(z / _PHI_STEP + _PHI_OFFSET)
    assert np.abs(got - special.ndtr(z)).max() <= 7e-16


@pytest.mark.parametrize("severity", SEVERITY_NAMES)
def test_math_face_severity_equals_numpy(severity):
    s = Scenario.preset("high", severity=severity)
    est = make_estimator("exact", s)
    beliefs = predict_array(s, np.array([5.0, -5.0, 0.3, 3.0, 0.2]))
    rng = np.random.default_rng(5)
    for n in (0, 1, 4, s.horizon):
        b = beliefs[n]
        scalar_belief = Belief(*(float(getattr(b, f)) for f in b.__dataclass_fields__))
        for v, th in zip(rng.uniform(-4, 8, 50), rng.uniform(-np.pi, np.pi, 50)):
            ref = float(est.severity.expected(v, th, b, NUMPY))
            got = est.severity.expected(float(v), float(th), scalar_belief, MATH)
            assert got == pytest.approx(ref, rel=1e-13, abs=1e-10)


@pytest.mark.parametrize("severity", SEVERITY_NAMES)
def test_exact_risk_every_path_equals_generic_form(severity):
    """One state against a scalar belief (Python floats), a batch against one belief, a batch
    against per-step beliefs, mixed near and far: all equal the generic form's R."""
    s = Scenario.preset("medium", severity=severity)
    est = make_estimator("exact", s)
    beliefs = predict_array(s, np.array([5.0, -5.0, 1.2, 3.0, 0.1]))
    rng = np.random.default_rng(6)
    for n in (1, 3):
        b = beliefs[n]
        egos = np.column_stack(
            [
                float(b.x) + rng.uniform(-9, 9, 400),
                float(b.y) + rng.uniform(-9, 9, 400),
                rng.uniform(-np.pi, np.pi, 400),
                rng.uniform(-4, 8, 400),
            ]
        )
        ref = np.asarray(est._risk(egos, b, NUMPY))
        scale = np.asarray(est.severity.expected(egos[:, 3], egos[:, 2], b, NUMPY))
        assert 0 < np.mean(ref > 0) < 1
        batch = est.risk(egos, b)
        assert np.all(np.abs(batch - ref) <= P_TOL * scale) and np.all(batch[ref == 0] == 0)
        scalar_belief = Belief(*(float(getattr(b, f)) for f in b.__dataclass_fields__))
        one = np.array([float(est.risk(e, scalar_belief)) for e in egos])
        assert np.all(np.abs(one - ref) <= P_TOL * scale) and np.all(one[ref == 0] == 0)
    steps = np.column_stack(
        [beliefs.x + 2.0, beliefs.y - 1.0, np.zeros_like(beliefs.x), np.full_like(beliefs.x, 4.0)]
    )
    ref = np.asarray(est._risk(steps, beliefs, NUMPY))
    scale = np.asarray(est.severity.expected(steps[:, 3], steps[:, 2], beliefs, NUMPY))
    assert np.all(ref > 0)
    assert np.all(np.abs(est.risk(steps, beliefs) - ref) <= P_TOL * scale)


def test_few_near_states_take_the_scalar_loop_and_agree():
    """Batches with up to SCALAR_LOOP_MAX near states (one belief per state) are integrated one by
    one; with one more they take the batch kernel. Both equal the generic form."""
    from risk_env.risk.estimators import SCALAR_LOOP_MAX

    s = Scenario.preset("high")
    est = make_estimator("exact", s)
    rng = np.random.default_rng(8)
    for near in (1, SCALAR_LOOP_MAX, SCALAR_LOOP_MAX + 1):
        n = near + 3  # three far states ride along
        meas = np.column_stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(-3, 3, n)])
        meas = np.column_stack([meas, np.full(n, 3.0), np.zeros(n)])
        b = predict_array(s, meas, steps=2)[2]
        offset = np.where(np.arange(n) < near, 2.0, 40.0)
        egos = np.column_stack([b.x + offset, b.y - 1.0, rng.uniform(-3, 3, n), rng.uniform(0, 6, n)])
        ref = np.asarray(est._risk(egos, b, NUMPY))
        scale = np.asarray(est.severity.expected(egos[:, 3], egos[:, 2], b, NUMPY))
        got = est.risk(egos, b)
        assert np.all(ref[:near] > 0) and np.all(got[near:] == 0)
        assert np.all(np.abs(got - ref) <= P_TOL * scale)
