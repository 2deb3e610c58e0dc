"""Rendering: frames are real pictures of the scene, headless, with and without a plan."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import risk_env
from risk_env import ENV_ID
from risk_env.render import rendering as R

ROOT = Path(__file__).resolve().parents[1]


def rgb_env(**kwargs):
    return gym.make(ENV_ID, render_mode="rgb_array", renderer="basic", **kwargs)


def has_colour(frame: np.ndarray, colour: tuple[int, int, int]) -> bool:
    return bool(np.any(np.all(frame == np.array(colour, dtype=np.uint8), axis=-1)))


def pixel(frame: np.ndarray, renderer: R.Renderer, x: float, y: float) -> tuple[int, ...]:
    u, w = np.round(renderer._to_px(x, y)).astype(int)
    return tuple(int(c) for c in frame[w, u])


def test_rgb_array_after_reset_and_steps(short_scenario):
    env = rgb_env(scenario=short_scenario)
    env.reset(seed=0)
    first = env.render()
    assert isinstance(first, np.ndarray) and first.dtype == np.uint8
    assert first.ndim == 3 and first.shape == (R.SIZE[1], R.SIZE[0], 3)
    assert first.std() > 1.0
    for _ in range(3):
        env.step(np.array([4.0, 0.0], dtype=np.float32))
    later = env.render()
    assert later.shape == first.shape and not np.array_equal(first, later)  # the scene moved
    renderer = env.unwrapped._view._renderer
    ego = env.unwrapped._ego_pose
    # The ego disc is drawn where the ego is (behind its centre: the heading line is white).
    assert pixel(later, renderer, ego[0] - 0.7, ego[1]) == R.EGO
    obj = env.unwrapped.object_measurement
    assert pixel(later, renderer, obj[0], obj[1] - 0.7) == R.OBJECT
    for colour in (R.PATH, R.GOAL, R.BOX_NEAR):
        assert has_colour(later, colour)
    env.close()


def test_plan_is_drawn_and_cleared():
    env = rgb_env()
    env.reset(seed=0)
    plain = env.render()
    assert not has_colour(plain, R.PLAN)
    xy = np.column_stack([np.linspace(-10.0, 10.0, 7), np.full(7, 10.0)])
    env.unwrapped.set_plan(xy)
    np.testing.assert_array_equal(env.unwrapped.plan, xy)
    planned = env.render()
    assert has_colour(planned, R.PLAN)
    assert pixel(planned, env.unwrapped._view._renderer, 5.0, 10.0) == R.PLAN
    env.unwrapped.set_plan(None)
    np.testing.assert_array_equal(env.render(), plain)
    env.unwrapped.set_plan(xy)
    env.reset()
    assert env.unwrapped.plan is None
    with pytest.raises(ValueError, match=r"shape \(M, 2\)"):
        env.unwrapped.set_plan(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="non-finite"):
        env.unwrapped.set_plan(np.array([[0.0, np.nan]]))


def test_human_mode_under_the_dummy_driver():
    env = gym.make(ENV_ID, render_mode="human")
    env.reset(seed=0)  # renders itself
    assert env.render() is None
    env.step(np.array([1.0, 0.0], dtype=np.float32))
    env.close()
    env.close()


def test_render_without_mode_warns_and_before_reset_raises():
    env = gym.make(ENV_ID).unwrapped
    env.reset()
    with pytest.warns(UserWarning, match="without a render_mode"):
        assert env.render() is None
    with pytest.raises(gym.error.ResetNeeded):
        gym.make(ENV_ID, render_mode="rgb_array").unwrapped.render()


def test_rgb_array_is_headless_in_a_fresh_process():
    # No DISPLAY and no SDL_VIDEODRIVER: rendering must pick the dummy driver by itself.
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "SDL_VIDEODRIVER", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    script = textwrap.dedent(
        """
        import gymnasium as gym, numpy as np, os, risk_env
        env = gym.make("RiskCrossing-v0", render_mode="rgb_array")
        env.reset(seed=0)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.std() > 1.0
        print(os.environ["SDL_VIDEODRIVER"], frame.shape)
        """
    )
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[0] == "dummy"


def test_every_object_and_its_boxes_are_drawn():
    env = rgb_env(scene="two_crossing", uncertainty="medium")
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.array([2.0, 0.0], dtype=np.float32))
    frame = env.render()
    renderer = env.unwrapped._view._renderer
    for x, y, theta, *_ in env.unwrapped.object_measurements:  # each disc, beside its heading line
        assert pixel(frame, renderer, x + 0.7 * np.sin(theta), y - 0.7 * np.cos(theta)) == R.OBJECT
    # each object's nearest truncation box: its left edge, at the belief's mean height
    for i, measurement in enumerate(env.unwrapped.object_measurements):
        belief = risk_env.predict(env.unwrapped.scenario.for_object(i), measurement, steps=1)[1]
        edge = renderer._to_px(float(belief.x - belief.half_x), float(belief.y))
        u, w = np.round(edge).astype(int)
        assert any(tuple(frame[w, u + k]) == R.BOX_NEAR for k in (-1, 0, 1)), i
    env.close()
