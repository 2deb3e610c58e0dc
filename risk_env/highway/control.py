"""Our unicycle's input as highway-env's action: the kinematic bicycle's acceleration and steering
that make the controlled vehicle end a step where the unicycle would (see
:mod:`risk_env.highway.adapter` for the approximation)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from risk_env.highway.common import slip_angle

MIN_TURN_SPEED = 0.5
"""Below this mean speed [m/s] the steering for a turn rate is computed as at this speed."""
STAND_SPEED = 0.1
"""When both the asked and the current speed [m/s] are below this, the car stands (it moves under
5 cm in a step) and its wheels are set straight: a standing car cannot turn, and steering it only
swings its direction of travel (heading plus slip angle, what the MPC plans with) away from its body
(by up to 0.7 rad at full lock, so that the discs of a car of several discs lie across the car)."""


def highway_action(
    v: float, omega: float, speed: float, steering: float, dt: float, half_length: float, action_type: Any
) -> tuple[np.ndarray, float]:
    r"""$(v, \omega)$ [m/s, rad/s] held for ``dt`` [s], from the current ``speed`` [m/s] and
    ``steering`` [rad] of a vehicle of half length ``half_length`` [m], as the normalised action
    ``(2,)`` float32 of highway-env's ``action_type`` (a ``ContinuousAction``), and the steering
    angle [rad] it applies: acceleration ``(v - speed) / dt``, and the steering whose kinematic
    bicycle turns at $\omega$ at the step's mean speed (:func:`slip_for`); straight wheels for a car
    that stands (:data:`STAND_SPEED`)."""
    accel = (v - speed) / dt
    mean = 0.5 * (v + speed)
    if abs(mean) < MIN_TURN_SPEED:
        mean = math.copysign(MIN_TURN_SPEED, mean if mean != 0 else 1.0)
    lo, hi = action_type.steering_range
    if max(abs(v), abs(speed)) < STAND_SPEED:
        steering = 0.0
    else:
        beta = slip_for(omega, mean, half_length, slip_angle(steering), slip_angle(hi), dt)
        steering = float(np.clip(math.atan(2.0 * math.tan(beta)), lo, hi))
    a_lo, a_hi = action_type.acceleration_range
    normalised = np.array(
        [2.0 * (accel - a_lo) / (a_hi - a_lo) - 1.0, 2.0 * (steering - lo) / (hi - lo) - 1.0]
    )
    return np.clip(normalised, -1.0, 1.0).astype(np.float32), steering


def slip_for(
    omega: float, mean_speed: float, half_length: float, beta_now: float, beta_max: float, dt: float
) -> float:
    r"""The slip angle $\beta$ [rad] whose step ends at the heading the unicycle predicts.

    Changing the steering turns the direction of travel at once by $\beta - \beta_{now}$; then
    it turns at $\bar v \sin(\beta) / (l/2)$ for $T$ ($\bar v$ = ``mean_speed``, $l$ the length).
    Solve $\beta - \beta_{now} + T \bar v \sin(\beta) / (l/2) = \omega T$ (Newton from the
    small-angle solution), so the course at the end of the step is the model's (the chord's
    direction then differs by $(\beta - \beta_{now}) / 2$, instead of the whole jump).
    """
    gain = mean_speed / half_length

    def residual(b: float) -> float:
        return (b - beta_now) / dt + gain * math.sin(b) - omega

    slope0 = 1.0 / dt + gain
    beta = (omega + beta_now / dt) / slope0 if slope0 > 0 else 0.0
    for _ in range(4):
        slope = 1.0 / dt + gain * math.cos(beta)
        if slope <= 0:  # fast reversing: no monotone solution; the small-angle one stands
            break
        beta -= residual(beta) / slope
    return float(np.clip(beta, -beta_max, beta_max))
