import math

import casadi as ca
import numpy as np

from risk_env.models import path
from risk_env.models.ops import CASADI
from risk_env.scenario.scenario import ReferencePath, Scenario

PAPER = Scenario().path


def test_paper_path_ends():
    x, y, th = path.point(PAPER, -95.0)
    assert (round(float(x), 2), round(float(y), 2)) == (-28.72, 18.45)
    assert round(math.degrees(float(th)), 1) == -16.3
    np.testing.assert_allclose(path.point(PAPER, 0.0), (65.0, 5.0, 0.0), atol=1e-12)


def test_closed_form_of_the_appendix():
    lam = np.linspace(-95, 20, 50)
    k = 0.003
    x, y, th = path.point(PAPER, lam)
    np.testing.assert_allclose(x, 65 + np.sin(k * lam) / k, atol=1e-9)
    np.testing.assert_allclose(y, 5 + (1 - np.cos(k * lam)) / k, atol=1e-9)
    np.testing.assert_allclose(th, k * lam)


def test_arc_length_and_heading_are_consistent():
    for p in (
        PAPER,
        ReferencePath(goal=(1.0, -2.0, 0.7), curvature=-0.02, lambda_start=-50),
        ReferencePath(curvature=0.0),
    ):
        lam = np.linspace(p.lambda_start, 10, 400)
        x, y, th = path.point(p, lam)
        seg = np.hypot(np.diff(x), np.diff(y))
        np.testing.assert_allclose(seg, np.diff(lam), rtol=1e-5)
        np.testing.assert_allclose(np.arctan2(np.diff(y), np.diff(x)), th[:-1] + np.diff(th) / 2, atol=1e-6)


def test_projection_round_trip():
    rng = np.random.default_rng(1)
    for p in (
        PAPER,
        ReferencePath(goal=(1.0, -2.0, 0.7), curvature=-0.02, lambda_start=-50),
        ReferencePath(curvature=0.0),
    ):
        lam = rng.uniform(p.lambda_start, 5.0, 200)
        offset = rng.uniform(-8, 8, 200)
        x, y, th = path.point(p, lam)
        qx, qy = x - offset * np.sin(th), y + offset * np.cos(th)  # move along the normal
        np.testing.assert_allclose(path.project(p, qx, qy), lam, atol=1e-8)


def test_timing_law_on_the_path_advances_by_arc_length():
    lam = -60.0
    _, _, th = path.point(PAPER, lam)
    assert path.timing_law(PAPER, lam, th, 4.0, 0.5) == lam + 2.0
    assert math.isclose(path.timing_law(PAPER, lam, th + math.pi / 2, 4.0, 0.5), lam, abs_tol=1e-12)


def test_path_error_and_wrapping():
    x, y, th = path.point(PAPER, -40.0)
    e, lam = path.path_error_vector(PAPER, np.array([x, y, th + 2 * math.pi]), 3.0, 4.0)
    np.testing.assert_allclose(e, [0, 0, 0, -1.0], atol=1e-9)
    assert math.isclose(lam, -40.0, abs_tol=1e-9)


def test_casadi_face():
    lam = ca.SX.sym("l")
    f = ca.Function("f", [lam], [ca.vertcat(*path.point(PAPER, lam, CASADI))])
    for value in (-95.0, -10.0, 0.0, 7.0):
        np.testing.assert_allclose(np.array(f(value)).ravel(), path.point(PAPER, value), atol=1e-12)
