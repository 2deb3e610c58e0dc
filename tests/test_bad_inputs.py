"""Bad inputs found by trying the library as a new user would (issue 21): each gets an error that
names it, or works; and numpy scalars pass wherever Python numbers do."""

from __future__ import annotations

import functools
import json
import math
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import risk_env  # noqa: F401  (registers RiskCrossing-v0)
from agents import RMPC, SMPC
from agents.mpc.nlp.settings import SolverSettings
from risk_env import Scenario
from risk_env.risk.severity import make_severity
from risk_env.scenario.scenario import MAX_MASS, RISK_BOUNDS

WRONG_UNIT = (
    "risk_tolerance 1000 exceeds 2, the largest per-step risk of the 'injury' severity \\[injuries\\]"
)


# ------------------------------------------------------------------ a tolerance in another unit
def test_an_injury_tolerance_in_joules_is_named_everywhere() -> None:
    with pytest.raises(ValueError, match=WRONG_UNIT):
        Scenario.preset("low", severity="injury", risk_tolerance=1000)
    with pytest.raises(ValueError, match=WRONG_UNIT):
        gym.make("RiskCrossing-v0", severity="injury", risk_tolerance=1000)
    injury = Scenario.preset("low", severity="injury", horizon=3)
    for agent in (SMPC, RMPC):
        with pytest.raises(ValueError, match=WRONG_UNIT):
            agent(injury, risk_tolerance=1000)
    smpc = SMPC(injury, max_solve_time=math.inf)  # epsilon = 0: a quick build; epsilon is a parameter
    with pytest.raises(ValueError, match=WRONG_UNIT):
        smpc.risk_tolerance = 1000
    smpc.risk_tolerance = np.float32(0.005)
    assert smpc.risk_tolerance == pytest.approx(0.005)
    with pytest.raises(ValueError, match=WRONG_UNIT):
        SMPC.from_env(gym.make("RiskCrossing-v0", severity="injury"), risk_tolerance=1000.0)
    with pytest.raises(ValueError, match="risk_tolerance 1.5 exceeds 1, .* 'probability' severity"):
        Scenario.preset("low", severity="probability", risk_tolerance=1.5)
    # at the bound, and in J for the energy severities, any size passes
    assert Scenario.preset("low", severity="injury", risk_tolerance=2.0).risk_tolerance == 2.0
    assert Scenario.preset("low", severity="plastic", risk_tolerance=1e9).risk_tolerance == 1e9


def test_risk_bounds_are_the_severity_models_own() -> None:
    for name, (bound, unit) in RISK_BOUNDS.items():
        model = make_severity(Scenario.preset("low", severity=name))
        assert (model.upper_bound, model.unit) == (bound, unit)


def test_the_highway_wrapper_takes_the_tolerance_in_the_severitys_unit() -> None:
    pytest.importorskip("highway_env")
    from risk_env.highway import RiskCostWrapper, make_intersection_env

    with pytest.raises(ValueError, match=WRONG_UNIT):
        RiskCostWrapper(make_intersection_env(), severity="injury", risk_tolerance=1000)


# ------------------------------------------------------------------ masses
def test_a_mass_beyond_any_road_user_is_named() -> None:
    """1e308 kg made the risk inf and the reward NaN; up to MAX_MASS every number stays finite."""
    with pytest.raises(ValueError, match=r"object\.mass must be at most 1e\+30 kg, got 1e\+308 kg"):
        gym.make("RiskCrossing-v0", object_mass=1e308)
    with pytest.raises(ValueError, match=r"ego\.mass must be at most"):
        Scenario.preset("low", ego_mass=1e31)
    with pytest.raises(ValueError, match=r"objects\[1\]\.mass must be at most"):
        Scenario.preset("low", objects=[{}, {"mass": 1e200}])
    env = gym.make("RiskCrossing-v0", object_mass=MAX_MASS, ego_mass=MAX_MASS, uncertainty="high")
    env.reset(seed=0)
    for _ in range(20):
        _, reward, terminated, truncated, info = env.step(np.array([4.0, 0.0], dtype=np.float32))
        assert math.isfinite(reward) and math.isfinite(info["risk"])
        if terminated or truncated:
            break
    assert info["episode_risk"] > 1e30  # the collision energy scales with the mass, finitely


# ------------------------------------------------------------------ the highway-env wrapper and adapter
def test_wrapper_rejects_a_scenario_of_another_step_and_bad_seeds() -> None:
    pytest.importorskip("highway_env")
    from risk_env.highway import RiskCostWrapper, highway_scenario, make_intersection_env

    env = make_intersection_env()
    with pytest.raises(ValueError, match=r"scenario\.dt = 0\.1 s, but one step of the env lasts 0\.5 s"):
        RiskCostWrapper(env, scenario=Scenario.preset("low", dt=0.1))
    with pytest.raises(ValueError, match=r"scenario\.dt = 1 s, but one step of the env lasts 0\.5 s"):
        RiskCostWrapper(env, dt=1.0)  # an override that changes the step
    assert RiskCostWrapper(env, scenario=highway_scenario(env, "medium")).scenario.dt == 0.5
    with pytest.raises(TypeError, match=r"seed must be an integer .*'abc' \(str\)"):
        RiskCostWrapper(env, seed="abc")
    with pytest.raises(ValueError, match="seed must be an integer >= 0, got -1"):
        RiskCostWrapper(env, seed=-1)
    wrapped = RiskCostWrapper(
        env, seed=np.int64(3), risk_tolerance=np.float32(0.5), vehicle_index=np.int64(0)
    )
    assert wrapped.scenario.risk_tolerance == 0.5
    wrapped.reset(seed=1)


def test_adapter_needs_an_agent_factory_and_takes_numpy_numbers() -> None:
    pytest.importorskip("highway_env")
    from risk_env.highway import IntersectionAdapter, make_intersection_env

    env = make_intersection_env()
    with pytest.raises(
        TypeError, match=r"make_agent must be callable, Scenario -> agent .* None \(NoneType\)"
    ):
        IntersectionAdapter(env, None)
    with pytest.raises(TypeError, match=r"switch_ahead must be a real number .*'2' \(str\)"):
        IntersectionAdapter(env, RMPC, switch_ahead="2")
    uncapped = functools.partial(RMPC, max_solve_time=math.inf)
    adapter = IntersectionAdapter(
        env,
        uncapped,
        risk_tolerance=np.float32(5.0),
        switch_ahead=np.float64(2.0),
        slots=np.int64(2),
        warm_up=False,  # one step: its own NLPs only (the warm-up is tests/test_warmup.py's)
    )
    assert adapter.slots == 2 and type(adapter.slots) is int
    obs, _ = env.reset(seed=0)
    action, _ = adapter.predict(obs)
    assert action.shape == (2,) and adapter.agent.slots == 2


# ------------------------------------------------------------------ the SMPC's arguments
@pytest.mark.parametrize(
    ("value", "error", "match"),
    [
        (math.nan, TypeError, r"samples must be an integer .*nan \(float\)"),
        (math.inf, TypeError, r"samples must be an integer .*inf \(float\)"),
        ("abc", TypeError, r"samples must be an integer .*'abc' \(str\)"),
        (100.0, TypeError, r"samples must be an integer .*100\.0 \(float\)"),
        (True, TypeError, "samples must be an integer, got the bool True"),
        (0, ValueError, "samples must be an integer >= 1, got 0"),
    ],
)
@pytest.mark.parametrize("name", ["samples", "pilot_samples"])
def test_smpc_sample_counts_are_integers(name: str, value: object, error: type, match: str) -> None:
    with pytest.raises(error, match=match.replace("samples", name)):
        SMPC(Scenario.preset("low"), risk="monte_carlo", **{name: value})


@pytest.mark.parametrize("name", ["risk_budget", "risk_weight"])
def test_budget_and_weight_are_numbers_not_strings(name: str) -> None:
    scenario = Scenario.preset("low", severity="probability", horizon=2)
    with pytest.raises(TypeError, match=rf"{name} must be .* a finite number >= 0, got '5' \(str\)"):
        SMPC(scenario, **{name: "5"})
    assert getattr(SMPC(scenario, **{name: np.float32(0.5)}, max_solve_time=math.inf), name) == 0.5


def test_mpc_risk_tolerance_is_a_number_not_a_string() -> None:
    with pytest.raises(TypeError, match=r"risk_tolerance must be a real number .*'5' \(str\)"):
        SMPC(Scenario.preset("low"), risk_tolerance="5")


# ------------------------------------------------------------------ numpy scalars
def test_mpcs_take_numpy_scalars_wherever_they_take_python_numbers() -> None:
    scenario = Scenario.preset("medium", risk_tolerance=500.0, horizon=3)
    agent = SMPC(
        scenario,
        risk="monte_carlo",
        samples=np.int64(30),
        pilot_samples=np.int32(10),
        bandwidth=np.float32(0.05),
        risk_tolerance=np.float64(400.0),
        risk_weight=np.float32(1.0),
        tol=np.float32(1e-4),
        max_iter=np.int64(80),
        backoff=np.float32(1e-3),
        cold_starts=np.int64(2),
        seed=np.int64(4),
        jit_opt=np.int64(0),
        max_solve_time=np.float32(0.05),
        soft_penalty=np.float32(1e4),
        object_slots=np.int64(1),
    )
    assert agent.samples == 30 and agent.max_solve_time == pytest.approx(0.05)
    assert (agent.settings.max_iter, agent.cold_starts, agent.seed) == (80, 2, 4)
    assert type(agent.settings.max_iter) is int and type(agent.settings.tol) is float
    obs, _ = gym.make("RiskCrossing-v0", scenario=scenario).reset(seed=0)
    uncapped = RMPC(scenario, max_solve_time=np.float64(math.inf), max_iter=np.int32(100))
    action, _ = uncapped.predict(obs)
    assert uncapped.last_solve.success and np.all(np.isfinite(action))
    settings = SolverSettings(max_iter=np.int64(10), rungs=np.int64(2), time_limit=np.float32(0.1))
    assert settings.rung_limits()[1][0] == 5


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"max_solve_time": "0.05"}, TypeError, r"max_solve_time must be a real number .*'0\.05' \(str\)"),
        ({"max_solve_time": 0.0}, ValueError, "max_solve_time must be a time > 0"),
        ({"max_solve_time": math.nan}, ValueError, "max_solve_time must be a time > 0"),
        ({"cold_starts": np.float64(2.0)}, TypeError, "cold_starts must be an integer"),
        ({"backoff": "1e-3"}, TypeError, "backoff must be a real number"),
        ({"backoff": -1e-3}, ValueError, "backoff must be >= 0"),
        ({"seed": -1}, ValueError, "seed must be an integer >= 0, got -1"),
        ({"seed": "abc"}, TypeError, r"seed must be an integer .*'abc'"),
        ({"jit_opt": 2.5}, TypeError, "jit_opt must be an integer"),
        ({"tol": "small"}, TypeError, "tol must be a real number"),
        ({"max_iter": np.float32(50)}, TypeError, "max_iter must be an integer"),
        ({"soft_penalty": math.inf}, ValueError, "soft_penalty must be finite"),
    ],
)
def test_mpc_arguments_of_the_wrong_kind_are_named(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        RMPC(Scenario.preset("low"), **kwargs)


# ------------------------------------------------------------------ PPO
def _policy_copy(tmp_path: Path, metadata: str | None) -> Path:
    from agents.ppo import shipped_model

    target = tmp_path / "policy.zip"
    shutil.copy(shipped_model("penalty"), target)
    if metadata is not None:
        (tmp_path / "policy.json").write_text(metadata)
    return target


def test_ppo_load_names_a_scenario_that_is_not_one(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    from agents.ppo import PPOAgent, shipped_model

    with pytest.raises(TypeError, match=r"scenario must be a risk_env Scenario .*got 'medium' \(str\)"):
        PPOAgent.load(shipped_model("penalty"), scenario="medium")
    agent = PPOAgent.load(shipped_model("penalty"), scenario=Scenario.preset("medium", risk_tolerance=500.0))
    assert agent.context is not None and agent.context.epsilon == 500.0


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("{not json", r"policy\.json is not valid JSON \(Expecting property name"),
        ("[1, 2]", r"policy\.json must hold a JSON object .*\[1, 2\] \(list\)"),
        ('{"limits": [0, 8]}', r"policy\.json: 'limits' must be a JSON object, got \[0, 8\]"),
        ('{"limits": {"v_min": "0"}}', r"policy\.json: limits\['v_min'\] must be a number, got '0' \(str\)"),
        ('{"limits": {"v_min": 0}}', r"policy\.json: limits \{'v_min': 0\} does not fit .*missing"),
        ('{"args": "x", "limits": {}}', r"policy\.json: 'args' must be a JSON object"),
        ('{"features": "29"}', r"policy\.json: 'features' must be a JSON integer"),
    ],
)
def test_ppo_load_names_a_damaged_metadata_file(tmp_path: Path, text: str, match: str) -> None:
    pytest.importorskip("stable_baselines3")
    from agents.ppo import PPOAgent

    with pytest.raises(ValueError, match=match):
        PPOAgent.load(_policy_copy(tmp_path, text))


def test_ppo_load_names_a_feature_spec_that_does_not_fit(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    from agents.ppo import PPOAgent, shipped_model

    meta = json.loads(shipped_model("penalty").with_suffix(".json").read_text())
    meta["feature_spec"]["steps"] = [2, "four"]
    with pytest.raises(
        ValueError, match=r"policy\.json: feature_spec .* does not fit \(steps must be an integer"
    ):
        PPOAgent.load(_policy_copy(tmp_path, json.dumps(meta)))
    meta["feature_spec"] = {"prediction": True, "window": 3}
    with pytest.raises(
        ValueError, match=r"policy\.json: feature_spec .* unexpected keyword argument 'window'"
    ):
        PPOAgent.load(_policy_copy(tmp_path, json.dumps(meta)))
    del meta["feature_spec"]  # a conditioned policy's metadata without its spec: the count disagrees
    with pytest.raises(ValueError, match="was trained on 29 features; this version has 14"):
        PPOAgent.load(_policy_copy(tmp_path, json.dumps(meta)))
    bare = tmp_path / "bare"
    bare.mkdir()
    with pytest.raises(ValueError, match=r"policy\.json is missing: pass scenario="):
        PPOAgent.load(_policy_copy(bare, None))
