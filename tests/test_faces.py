"""The faces of each model agree: Python floats (MATH, the single env), numpy arrays (the batched
env) and CasADi (the MPC) evaluate the same formulas to 1e-12."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy import special

from risk_env import Scenario, make_estimator, observation, predict
from risk_env.envs.transition import move_object, observe
from risk_env.envs.variations import DRAWS, Variations, draw, vary
from risk_env.models.dynamics import unicycle_step
from risk_env.models.ops import CASADI, MATH, NUMPY
from risk_env.models.path import PathBatch, path_error, point, project
from risk_env.models.truncnorm import transform
from risk_env.prediction.belief import Belief, predict_step

TOL = 1e-12
RNG = np.random.default_rng(20)


def casadi_eval(fn, *args: np.ndarray) -> np.ndarray:
    """``fn`` built on CasADi symbols, evaluated entry by entry at ``args``."""
    syms = [ca.SX.sym(f"a{i}") for i in range(len(args))]
    out = fn(*syms)
    f = ca.Function("f", syms, list(out) if isinstance(out, tuple) else [out])
    res = [f(*entry) for entry in zip(*args, strict=True)]
    return np.array([[float(v) for v in (r if isinstance(r, (list, tuple)) else [r])] for r in res])


def math_eval(fn, *args: np.ndarray) -> np.ndarray:
    out = [fn(*(float(a) for a in entry)) for entry in zip(*args, strict=True)]
    return np.array([o if isinstance(o, tuple) else (o,) for o in out], dtype=float)


def numpy_eval(fn, *args: np.ndarray) -> np.ndarray:
    out = fn(*args)
    return np.stack(np.broadcast_arrays(*(out if isinstance(out, tuple) else (out,))), axis=-1)


def assert_faces_agree(fn, *args: np.ndarray, casadi: bool = True) -> None:
    """``fn(*args, ops)`` on each face: numpy arrays, Python floats, CasADi; equal to TOL."""
    ref = numpy_eval(lambda *a: fn(*a, NUMPY), *args)
    np.testing.assert_allclose(math_eval(lambda *a: fn(*a, MATH), *args), ref, rtol=TOL, atol=TOL)
    if casadi:
        got = casadi_eval(lambda *a: fn(*a, CASADI), *args)
        np.testing.assert_allclose(got, ref, rtol=TOL, atol=TOL)


def test_elementary_functions() -> None:
    a = np.concatenate([RNG.uniform(-9, 9, 200), 10.0 ** RNG.uniform(-12, -3, 50), [0.0, 1e-4, -1e-4]])
    assert_faces_agree(lambda x, ops: ops.sinc(x), a)
    assert_faces_agree(lambda x, ops: ops.wrap_angle(x), 3 * a)
    assert_faces_agree(lambda x, ops: ops.norm_cdf(x), a)
    assert_faces_agree(lambda x, y, ops: ops.hypot(x, y), a, RNG.uniform(-9, 9, len(a)))
    p = np.concatenate([RNG.uniform(0, 1, 200), 10.0 ** RNG.uniform(-300, -1, 50)])
    assert_faces_agree(lambda x, ops: ops.norm_ppf(x), p, casadi=False)  # CasADi: erfinv, not exact
    assert MATH.norm_ppf(0.0) == -math.inf and MATH.norm_ppf(1.0) == math.inf
    np.testing.assert_allclose(NUMPY.sinc(a), np.sinc(a / np.pi), rtol=TOL)
    np.testing.assert_allclose(MATH.norm_ppf(0.3), special.ndtri(0.3), rtol=TOL)


def test_stack_and_pack_broadcast_scalars() -> None:
    x, y = np.arange(3.0), np.arange(3.0) + 10
    np.testing.assert_array_equal(NUMPY.stack([x, 2.0, y]), np.stack([x, np.full(3, 2.0), y], -1))
    packed = NUMPY.pack([x, 2.0, y])
    assert packed.flags.c_contiguous and packed.dtype == float
    np.testing.assert_array_equal(packed, NUMPY.stack([x, 2.0, y]))
    np.testing.assert_array_equal(MATH.pack([1.0, 2.0]), [1.0, 2.0])


def test_dynamics() -> None:
    n = 100
    pose = RNG.uniform(-20, 20, (3, n))
    v, omega = RNG.uniform(-4, 8, n), np.concatenate([RNG.uniform(-0.8, 0.8, n - 2), [0.0, 1e-9]])
    assert_faces_agree(lambda x, y, t, v_, w, ops: unicycle_step(x, y, t, v_, w, 0.5, ops), *pose, v, omega)


@pytest.mark.parametrize("curvature", [0.003, 0.0, -0.007])
def test_path(curvature: float) -> None:
    path = Scenario.preset(curvature=curvature).path
    n = 80
    x, y = RNG.uniform(-40, 70, n), RNG.uniform(-20, 40, n)
    theta, lam = RNG.uniform(-7, 7, n), RNG.uniform(-100, 10, n)
    assert_faces_agree(lambda lam_, ops: point(path, lam_, ops), lam)
    assert_faces_agree(lambda x_, y_, ops: project(path, x_, y_, ops), x, y)
    assert_faces_agree(
        lambda x_, y_, t, l_, ops: path_error(path, x_, y_, t, 1.0, l_, 4.0, ops), x, y, theta, lam
    )
    batch = PathBatch(np.full(n, curvature), path.goal)  # one goal for every entry
    np.testing.assert_allclose(np.stack(point(batch, lam), -1), numpy_eval(lambda a: point(path, a), lam))


def test_prediction_step_and_faces() -> None:
    s = Scenario.preset("medium")
    m = RNG.uniform([-20, -20, -3, -2, -0.5], [20, 20, 3, 5, 0.5], (40, 5))
    full = predict(s, m.T, steps=3)
    for n in (1, 3):
        step = predict_step(s, tuple(m.T), n, NUMPY)
        np.testing.assert_array_equal(step.as_array(), full[n].as_array())
        floats = [predict_step(s, tuple(row.tolist()), n, MATH).as_array() for row in m]
        np.testing.assert_allclose(floats, step.as_array(), rtol=TOL, atol=TOL)


def test_truncated_normal_draws() -> None:
    n = 300
    u = np.concatenate([RNG.uniform(0, 1, n - 3), [0.0, 1e-300, 1.0 - 2**-53]])
    mean, sigma = RNG.uniform(-5, 5, n), np.where(np.arange(n) % 10 == 0, 0.0, RNG.uniform(0.01, 3, n))
    lo = mean + RNG.uniform(-6, 4, n)  # far tails, one-sided boxes, empty ones
    hi = lo + np.where(np.arange(n) % 15 == 0, 0.0, RNG.uniform(0.0, 8, n))
    assert_faces_agree(transform, u, mean, sigma, lo, hi, casadi=False)
    got = transform(u, mean, sigma, lo, hi)
    assert np.all((got >= lo) & (got <= np.maximum(lo, hi)))


@pytest.mark.parametrize("motion", ["paper", "sampled"])
def test_transition(motion: str) -> None:
    """One state in floats == a batch in arrays: the move, and the observation with three objects
    in four slots, each present in some copies only."""
    s = Scenario.preset("high")
    n, m, slots = 60, 3, 4
    ego = RNG.uniform([-20, -20, -4, -4, -0.8], [60, 20, 4, 8, 0.8], (n, 5))
    obj = RNG.uniform([-20, -20, -3, -2, -0.5], [20, 20, 3, 5, 0.5], (m, n, 5))
    present = RNG.uniform(0, 1, (m, n)) < 0.7
    present[0, :5] = True  # copies with every object
    present[:, 5:10] = True
    radii = (3.0, 2.5, 4.0)
    u = RNG.uniform(0, 1, (n, 3)) if motion == "sampled" else None
    belief = predict_step(s, tuple(obj[0].T), 1, NUMPY)
    batch = np.stack(move_object(belief, tuple(obj[0].T), u, NUMPY), -1)
    path = s.path
    objects = [tuple(o.T) for o in obj]
    seen = observe(
        PathBatch(np.full(n, path.curvature), path.goal),
        4.0,
        radii,
        ego.T[:3],
        ego.T[3:],
        objects,
        slots,
        list(present),
        NUMPY,
    )
    assert seen.obs.shape == (n, observation.size(slots))
    for i in range(n):
        one = predict_step(s, tuple(obj[0, i].tolist()), 1, MATH)
        moved = move_object(one, tuple(obj[0, i].tolist()), None if u is None else u[i].tolist(), MATH)
        np.testing.assert_allclose(moved, batch[i], rtol=TOL, atol=TOL)
        e = ego[i].tolist()
        flags = [bool(p) for p in present[:, i]]
        single = observe(path, 4.0, radii, e[:3], e[3:], [o[i].tolist() for o in obj], slots, flags, MATH)
        np.testing.assert_allclose(single.obs, seen.obs[i], rtol=1e-7)  # float32
        np.testing.assert_allclose(single.path_error, seen.path_error[i], rtol=TOL, atol=TOL)
        for name in ("lam", "distance", "error_norm"):
            assert getattr(single, name) == pytest.approx(getattr(seen, name)[i], rel=TOL, abs=TOL)
        assert (single.collision, single.goal, single.closest) == (
            seen.collision[i],
            seen.goal[i],
            seen.closest[i],
        )
        # against the definitions: the nearest present object, a collision with any of them
        gaps = [np.hypot(e[0] - o[i, 0], e[1] - o[i, 1]) if p else np.inf for o, p in zip(obj, flags)]
        assert single.distance == pytest.approx(min(gaps), rel=TOL) and single.closest == int(np.argmin(gaps))
        assert single.collision == any(g <= r for g, r in zip(gaps, radii))
        parts = observation.split(single.obs)
        assert parts.present.tolist() == [*flags, False]
        np.testing.assert_allclose(
            parts.objects[:m][present[:, i]][:, :2], obj[present[:, i], i, :2], rtol=1e-6
        )


def test_variations_draw_faces_and_vary() -> None:
    base = Scenario.preset("low")
    u = RNG.uniform(-1, 1, (DRAWS, 50))
    batch = draw(base, u, Variations(curvature=0.01), NUMPY)
    for i in range(50):
        one = draw(base, u[:, i].tolist(), Variations(curvature=0.01))
        assert one.curvature == batch.curvature[i]  # clipped to the same limit
        np.testing.assert_allclose(one.ego, np.array(batch.ego)[:, i], rtol=TOL, atol=TOL)
        np.testing.assert_allclose(one.objects, np.array(batch.objects)[:, :, i], rtol=TOL, atol=TOL)
        assert one.count is None and batch.count is None
    rng, again = np.random.default_rng(4), np.random.default_rng(4)
    s = vary(base, rng)
    start = draw(base, again.uniform(-1.0, 1.0, size=DRAWS).tolist())
    assert (s.path.curvature, s.ego.start.as_tuple(), s.object.start.as_tuple(), s.object.speed) == (
        start.curvature,
        start.ego,
        start.objects[0][:3],
        start.objects[0][3],
    )


@pytest.mark.parametrize("name", ["exact", "worst_case", "grid", "monte_carlo"])
def test_risk_of_one_state_equals_the_array_form(name: str) -> None:
    s = Scenario.preset("high", risk_tolerance=100.0)
    est = make_estimator(name, s)
    meas = (5.0, -5.0, 1.3, 3.0, 0.1)
    belief = predict_step(s, meas, 2, MATH)
    array_belief = Belief(*(np.float64(v) for v in belief.as_array()))
    hits = 0
    for ego in RNG.uniform([-5, -15, -3, -4], [15, 5, 3, 8], (60, 4)):
        one = est.risk_one(tuple(ego.tolist()), belief, rng=np.random.default_rng(1))
        ref = float(est.risk(ego, array_belief, rng=np.random.default_rng(1)))
        assert type(one) is float and one == pytest.approx(ref, rel=TOL, abs=TOL)
        hits += one > 0
    assert 0 < hits < 60
