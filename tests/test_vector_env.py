"""The batched env: the same numbers as Gymnasium's vector envs of single envs, and clear errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import risk_env
import risk_env.prediction
from risk_env import Variations
from risk_env.envs.pcg64 import VECTORIZED_MIN, GeneratorBatch
from risk_env.envs.vector_env import SCALAR_COPIES, RiskCrossingVectorEnv

TOL = 1e-12
"""Relative tolerance between the single env (Python floats), the batched env's numpy path and its
one-by-one path: rounding of the same formulas through different elementary-function libraries."""
RISK_TOL = 1e-12 * 0.5 * 1000.0 * 8.0**2 * 2
"""Absolute tolerance on risks [J]: the exact risk's kernels (one state, a batch) agree to 1e-12 in
P, times the largest expected severity here (both masses 1000 kg, speeds up to 8 m/s)."""


MANY = [
    {"scene": "two_crossing", "object_motion": "sampled", "uncertainty": "high", "object_slots": 3},
    {
        "scene": "four_crossing",
        "randomize": True,
        "variations": Variations(object_count=True),
        "object_motion": "sampled",
        "uncertainty": "medium",
    },
    {
        "scene": "two_crossing",
        "risk_estimator": "monte_carlo",
        "object_motion": "sampled",
        "mc_samples": 50,
        "randomize": True,
    },
    {
        "objects": [
            {"start": (-2.0, 2.0, 1.4), "speed": 2.0},
            {"start": (8.0, 20.0, -1.6), "speed": 3.0, "mass": 1500.0, "radius": 2.0, "uncertainty": "high"},
            {"start": (20.0, -3.0, 1.7), "speed": 1.0, "sigma_growth": (0.5, 0.5, 0.5), "radius": 1.0},
        ],
        "risk_estimator": "worst_case",
        "object_motion": "sampled",
        "randomize": True,
        "variations": Variations(object_count=True),
    },
]
"""Several objects: scenes, more slots than objects, per-object uncertainty, mass and radius,
randomised counts, Monte Carlo and worst-case risk."""


def _flatten(tree, prefix=""):
    """Leaves of (nested) info dicts as ``{path: array}``; object arrays of final_obs expanded."""
    out = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            out.update(_flatten(value, f"{prefix}{key}/"))
        elif key == "final_obs":
            for i, obs in enumerate(value):
                out[f"{prefix}{key}/{i}"] = np.zeros(0) if obs is None else obs
        else:
            out[f"{prefix}{key}"] = np.asarray(value)
    return out


def _run(mode: str, autoreset: AutoresetMode, steps: int, num_envs: int = 3, **kwargs):
    """Results of a seeded run; modes ``numpy`` and ``one_by_one`` hold the batched env to one
    path, ``vectorized_rng`` to the batched generators."""
    if mode in ("vector_entry_point", "numpy", "one_by_one", "vectorized_rng"):
        env = gym.make_vec(
            risk_env.ENV_ID, num_envs, "vector_entry_point", autoreset_mode=autoreset, **kwargs
        )
        env.unwrapped.scalar_copies = {"numpy": 0, "one_by_one": num_envs}.get(mode, SCALAR_COPIES)
        if mode == "vectorized_rng":
            env.unwrapped._generators = GeneratorBatch(num_envs, vectorized=True)
    else:
        env = gym.make_vec(
            risk_env.ENV_ID, num_envs, mode, vector_kwargs={"autoreset_mode": autoreset}, **kwargs
        )
    rng = np.random.default_rng(7)
    results = [env.reset(seed=11)]
    for _ in range(steps):
        action = np.stack([rng.uniform(-1.0, 8.0, num_envs), rng.uniform(-0.8, 0.8, num_envs)], axis=-1)
        results.append(env.step(action.astype(np.float32)))
    env.close()
    return results


def _assert_close(a, b, atol: float, err_msg: str = "") -> None:
    """``np.testing.assert_allclose(a, b, rtol=TOL, atol=atol)``, which runs thousands of times
    here: real arrays of one shape within ``|a - b| <= atol + TOL |b|`` everywhere (its test, for
    finite numbers) pass without it; the rest (NaN, infinities, bools, a failure) go through it."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape == b.shape and a.dtype.kind in "fiu" and b.dtype.kind in "fiu":
        with np.errstate(invalid="ignore", over="ignore"):
            gap = np.abs(a.astype(np.float64) - b)
            if (gap <= atol + TOL * np.abs(b)).all() and np.isfinite(gap).all():
                return
    np.testing.assert_allclose(a, b, rtol=TOL, atol=atol, err_msg=err_msg)


def _assert_same(a, b) -> None:
    """Equal to :data:`TOL` (risks to :data:`RISK_TOL`), and the same episode ends."""
    ends = 0
    for step_a, step_b in zip(a, b, strict=True):
        for part_a, part_b in zip(step_a, step_b, strict=True):
            if isinstance(part_a, dict):
                fa, fb = _flatten(part_a), _flatten(part_b)
                assert fa.keys() == fb.keys()
                for key in fa:
                    atol = RISK_TOL if "risk" in key or "cost" in key else TOL
                    _assert_close(fa[key], fb[key], atol, err_msg=key)
            else:
                _assert_close(part_a, part_b, RISK_TOL)
        if len(step_a) == 5:
            ends += int(np.sum(step_a[2] | step_a[3]))
    assert ends >= 2, "the comparison should cover episode ends"


@pytest.mark.parametrize("autoreset", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize(
    "kwargs",
    [
        {},
        {"randomize": True, "object_motion": "sampled", "uncertainty": "high", "risk_tolerance": 100.0},
        {"risk_estimator": "monte_carlo", "object_motion": "sampled", "mc_samples": 50},
        {"severity": "injury", "object_motion": "sampled", "uncertainty": "high", "risk_tolerance": 0.005},
        *MANY,
    ],
)
def test_batched_equals_sync(autoreset, kwargs) -> None:
    """Single envs (Python floats) == the batched env's numpy path == its one-by-one path, over
    episodes of 12 steps (or shorter) and the resets between them (two or more per copy)."""
    kwargs = {"max_steps": 12, **kwargs}
    single = _run("sync", autoreset, 28, **kwargs)
    _assert_same(single, _run("numpy", autoreset, 28, **kwargs))
    _assert_same(single, _run("one_by_one", autoreset, 28, **kwargs))


@pytest.mark.parametrize("scene", ["paper", "four_crossing"])
def test_vectorised_generators_draw_what_each_copy_draws(scene) -> None:
    kwargs = {"randomize": True, "object_motion": "sampled", "max_steps": 15, "scene": scene}
    if scene != "paper":
        kwargs["variations"] = Variations(object_count=True)
    for estimator in ("exact", "monte_carlo"):
        single = _run("sync", AutoresetMode.SAME_STEP, 35, num_envs=5, risk_estimator=estimator, **kwargs)
        batched = _run(
            "vectorized_rng", AutoresetMode.SAME_STEP, 35, num_envs=5, risk_estimator=estimator, **kwargs
        )
        _assert_same(single, batched)


@pytest.mark.parametrize("scene", ["paper", "two_crossing"])
def test_large_batch_takes_the_vectorised_generators_and_agrees(scene) -> None:
    """128 copies: numpy path and batched generators by default; two copies against single envs."""
    kwargs = {
        "randomize": True,
        "object_motion": "sampled",
        "max_steps": 25,
        "uncertainty": "high",
        "scene": scene,
    }
    n = VECTORIZED_MIN
    env = gym.make_vec(risk_env.ENV_ID, n, "vector_entry_point", **kwargs)
    assert env.unwrapped._generators._batch is not None and env.unwrapped.scalar_copies < n
    actions = np.random.default_rng(3).uniform([-1.0, -0.8], [8.0, 0.8], (60, n, 2)).astype(np.float32)
    obs, _ = env.reset(seed=100)
    singles = [gym.make(risk_env.ENV_ID, **kwargs) for _ in (0, n - 1)]
    first = [single.reset(seed=100 + i)[0] for single, i in zip(singles, (0, n - 1), strict=True)]
    np.testing.assert_allclose(obs[[0, n - 1]], first, rtol=TOL)
    ended = np.zeros(2, dtype=bool)
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        for j, i in enumerate((0, n - 1)):
            if ended[j]:  # next-step autoreset: this step reset the copy
                expected = singles[j].reset()[0]
                np.testing.assert_allclose(obs[i], expected, rtol=TOL, atol=TOL)
                ended[j] = False
                continue
            o, r, te, tr, inf = singles[j].step(action[i])
            np.testing.assert_allclose(obs[i], o, rtol=TOL, atol=TOL)
            assert reward[i] == pytest.approx(r, rel=TOL, abs=TOL)
            assert info["risk"][i] == pytest.approx(inf["risk"], rel=TOL, abs=RISK_TOL)
            np.testing.assert_allclose(info["risk_terms"][i], inf["risk_terms"], rtol=TOL, atol=RISK_TOL)
            assert (terminated[i], truncated[i]) == (te, tr)
            ended[j] = te or tr


def test_batched_equals_async() -> None:
    kwargs = {"randomize": True, "object_motion": "sampled"}
    _assert_same(
        _run("async", AutoresetMode.NEXT_STEP, 50, num_envs=2, max_steps=20, **kwargs),
        _run("vector_entry_point", AutoresetMode.NEXT_STEP, 50, num_envs=2, max_steps=20, **kwargs),
    )


def test_default_mode_is_batched() -> None:
    env = gym.make_vec(risk_env.ENV_ID, num_envs=4)
    assert isinstance(env.unwrapped, RiskCrossingVectorEnv)
    obs, info = env.reset(seed=0)
    assert obs.shape == (4, 16) and obs.dtype == np.float32
    assert env.observation_space.contains(obs)
    assert info["risk"].shape == (4,) and info["path_error"].shape == (4, 4)


def test_disabled_autoreset_needs_masked_reset() -> None:
    env = RiskCrossingVectorEnv(num_envs=2, autoreset_mode="disabled", max_steps=2)
    env.reset(seed=0)
    action = np.tile([4.0, 0.0], (2, 1))
    env.step(action)
    *_, truncated, _ = env.step(action)
    assert truncated.all()
    with pytest.raises(gym.error.ResetNeeded, match="reset_mask"):
        env.step(action)
    obs, _ = env.reset(options={"reset_mask": np.array([True, False])})
    first, _ = RiskCrossingVectorEnv(num_envs=1).reset(seed=0)
    np.testing.assert_array_equal(obs[0], first[0])
    assert not np.array_equal(obs[1], first[0])


@pytest.mark.parametrize(
    ("action", "match"),
    [
        (np.array([[4.0, 0.0], [np.nan, 0.0]]), r"copies \[1\] are non-finite"),
        (np.array([[4.0, 0.0], [4.0, 2.0]]), r"copies \[1\] are outside"),
        (np.array([4.0, 0.0]), r"shape \(2, 2\)"),
    ],
)
def test_bad_actions_name_the_copy(action, match) -> None:
    env = RiskCrossingVectorEnv(num_envs=2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.step(action)


def test_bad_construction() -> None:
    with pytest.raises(ValueError, match="num_envs"):
        RiskCrossingVectorEnv(num_envs=0)
    with pytest.raises(TypeError, match="object_sped"):
        RiskCrossingVectorEnv(num_envs=2, object_sped=2.0)
    with pytest.raises(ValueError, match="takes no render_mode"):
        RiskCrossingVectorEnv(num_envs=2, render_mode="rgb_array")
    paper = risk_env.Scenario.preset("low")
    with pytest.raises(ValueError, match="takes no predictor"):
        RiskCrossingVectorEnv(num_envs=2, predictor=risk_env.prediction.ConstantPredictor(paper))
    with pytest.raises(ValueError, match="autoreset_mode"):
        RiskCrossingVectorEnv(num_envs=2, autoreset_mode="sometimes")
    env = RiskCrossingVectorEnv(num_envs=2)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="reset option"):
        env.reset(options={"mask": None})
