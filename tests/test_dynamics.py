import casadi as ca
import numpy as np
import pytest

from risk_env.models import dynamics


def test_straight_line():
    x = dynamics.step(np.array([1.0, 2.0, 0.3]), np.array([4.0, 0.0]), 0.5)
    np.testing.assert_allclose(x, [1 + 2 * np.cos(0.3), 2 + 2 * np.sin(0.3), 0.3], atol=1e-14)


@pytest.mark.parametrize("omega", [0.7, -1.3, 1e-3])
def test_constant_turn_stays_on_its_circle(omega):
    v, dt, th0 = 3.0, 0.5, 0.4
    start = np.array([0.0, 0.0, th0])
    traj = dynamics.rollout(start, np.array([v, omega]), dt, 20)
    radius = v / omega
    centre = np.array([-radius * np.sin(th0), radius * np.cos(th0)])
    np.testing.assert_allclose(np.hypot(*(traj[:, :2] - centre).T), abs(radius), rtol=1e-10)
    np.testing.assert_allclose(traj[:, 2], th0 + omega * dt * np.arange(21), atol=1e-12)
    # the paper's closed form (divides by omega)
    x1 = start + np.array(
        [
            v / omega * (np.sin(th0 + omega * dt) - np.sin(th0)),
            v / omega * (np.cos(th0) - np.cos(th0 + omega * dt)),
            omega * dt,
        ]
    )
    np.testing.assert_allclose(traj[1], x1, atol=1e-10)


def test_smooth_as_omega_vanishes():
    state = np.array([0.0, 0.0, 1.0])
    ref = dynamics.step(state, np.array([2.0, 0.0]), 0.5)
    for omega in (1e-3, 1e-5, 1e-8, -1e-8):
        np.testing.assert_allclose(
            dynamics.step(state, np.array([2.0, omega]), 0.5), ref, atol=2 * abs(omega)
        )


def test_batched_and_casadi_faces_agree():
    rng = np.random.default_rng(0)
    states = rng.normal(size=(50, 3))
    actions = np.column_stack([rng.uniform(-4, 8, 50), rng.choice([0.0, 1e-6, 0.5, -0.8], 50)])
    batched = dynamics.step(states, actions, 0.5)
    s, a = ca.SX.sym("s", 3), ca.SX.sym("a", 2)
    f = ca.Function("f", [s, a], [dynamics.casadi_step(s, a, 0.5)])
    for i in range(50):
        np.testing.assert_allclose(np.array(f(states[i], actions[i])).ravel(), batched[i], atol=1e-12)
        np.testing.assert_allclose(dynamics.step(states[i], actions[i], 0.5), batched[i], atol=0)
    jac = ca.Function("j", [s, a], [ca.jacobian(dynamics.casadi_step(s, a, 0.5), a)])
    assert np.all(np.isfinite(np.array(jac([0, 0, 0.2], [3.0, 0.0]))))
