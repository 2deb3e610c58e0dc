"""Property-based tests with Hypothesis (issue 14, item 5): fuzzed scenarios, actions and
observations against the invariants every step must keep.

- the env (single and batched): observations in the observation space; the risk finite and >= 0;
  cost == risk; the violation flag is risk > epsilon; the collision flag is the centre distance
  (from the true states) <= r_e + r_o; termination and truncation as documented; stepping past
  the end raises; the same seed gives the same trajectory, bit for bit;
- scenarios up to the observation bounds: accepted ones keep every observation in the Box,
  rejected ones say why with a ValueError;
- the agents (RMPC and the exact SMPC, short horizon): finite actions in the action space and
  within the rate limits, in closed loop and on fuzzed observations.

The default run fuzzes about 900 env steps and a few dozen agent decisions; the ``slow`` tests
repeat the env properties for over 10^4 steps and the agents' for some hundred decisions. Print the
counts with ``pytest -s``.
"""

from __future__ import annotations

import collections
import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agents import RMPC, SMPC
from agents.base import Policy
from risk_env import ENV_ID, ESTIMATOR_NAMES, OBJECT_MOTIONS, RISK_TOLERANCES, RiskCrossingEnv, Scenario
from risk_env import observation as ob
from risk_env.envs.transition import observe
from risk_env.models.path import point
from risk_env.scenario.scenario import OVERRIDES, RISK_BOUNDS, SEVERITY_NAMES, UNCERTAINTY_PRESETS

FUZZED: collections.Counter[str] = collections.Counter()
"""Fuzzed steps by test family (single-env steps, batched copy-steps, agent decisions)."""


@pytest.fixture(scope="module", autouse=True)
def _report_fuzzed_steps():
    yield
    steps = {k: v for k, v in FUZZED.items() if k != "rejected scenarios"}
    print(f"\nfuzzed steps: {steps}, total {sum(steps.values())}; {dict(FUZZED)}")


FAST = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
"""Env construction and solver builds vary in time on shared machines: no per-example deadline."""


def fuzz(examples: int) -> settings:
    """Hypothesis settings: ``examples`` examples, no deadline."""
    return settings(FAST, max_examples=examples)


# ---------------------------------------------------------------- strategies
def integral(low: int, high: int) -> st.SearchStrategy[Any]:
    """Integers as Python or numpy ints: every integral type must pass."""
    ints = st.integers(low, high)
    return st.one_of(ints, ints.map(np.int64), ints.map(np.int32))


def real(low: float, high: float) -> st.SearchStrategy[float]:
    return st.floats(low, high, allow_nan=False, allow_infinity=False)


@st.composite
def crossing_objects(draw: st.DrawFn, near: tuple[float, float]) -> dict[str, Any]:
    """One object as an ``objects=`` dict: within 15 m of ``near`` half of the time, else anywhere
    around the path; its own radius, mass and (sometimes) uncertainty."""
    if draw(st.booleans()):
        start = (near[0] + draw(real(-15, 15)), near[1] + draw(real(-15, 15)))
    else:
        start = (draw(real(-30, 80)), draw(real(-30, 30)))
    spec = {
        "start": (*start, draw(real(-math.pi, math.pi))),
        "speed": draw(real(-5.0, 5.0)),
        "turn_rate": draw(real(-0.5, 0.5)),
        "radius": draw(real(0.3, 3.0)),
        "mass": draw(real(100.0, 3000.0)),
    }
    own = draw(st.sampled_from((None, *UNCERTAINTY_PRESETS)))
    if own is not None:
        spec["uncertainty"] = own
    return spec


@st.composite
def scenarios(
    draw: st.DrawFn, max_steps: int = 20, horizon: int | None = None, many: bool = False
) -> Scenario:
    """The paper's scenario with fuzzed starts, speeds, path, tolerance and severity; ``many``:
    with up to two more objects half of the time (:func:`crossing_objects`).

    The ego starts near the path (so episodes reach the goal sometimes), the object within 15 m
    of it half of the time (so collisions and nonzero risk happen).
    """
    base = Scenario.preset(draw(st.sampled_from(UNCERTAINTY_PRESETS)))
    curvature = draw(real(-0.01, 0.01))
    path = base.replace(curvature=curvature).path
    lam = draw(real(-95.0, -1.0))
    px, py, pth = point(path, lam)
    offset = draw(real(-4.0, 4.0))
    ego_start = (
        float(px - math.sin(pth) * offset),
        float(py + math.cos(pth) * offset),
        float(pth + draw(real(-0.6, 0.6))),
    )
    if draw(st.booleans()):
        object_start = (ego_start[0] + draw(real(-15, 15)), ego_start[1] + draw(real(-15, 15)))
    else:
        object_start = (draw(real(-30, 80)), draw(real(-30, 30)))
    severity = draw(st.sampled_from(SEVERITY_NAMES))
    bound = RISK_BOUNDS[severity][0]  # a tolerance in the severity's own unit
    joules = st.one_of(st.sampled_from(RISK_TOLERANCES), real(0.0, 3000.0))
    overrides: dict[str, Any] = {
        "curvature": curvature,
        "ego_start": ego_start,
        "object_start": (*object_start, draw(real(-math.pi, math.pi))),
        "object_speed": draw(real(-5.0, 5.0)),
        "object_turn_rate": draw(real(-0.5, 0.5)),
        "v_ref": draw(real(0.0, 8.0)),
        "initial_input": (draw(real(-4.0, 8.0)), draw(real(-0.8, 0.8))),
        "risk_tolerance": draw(joules if math.isinf(bound) else st.one_of(st.just(0.0), real(0.0, bound))),
        "severity": severity,
        "dt": draw(st.sampled_from((0.5, 0.5, 0.2, 1.0))),
        "max_steps": draw(integral(1, max_steps)),
        "mc_samples": draw(integral(1, 64)),
        "grid_points": draw(integral(2, 12)),
    }
    if horizon is not None:
        overrides["horizon"] = horizon
    if many and draw(st.booleans()):
        overrides["objects"] = [{}, *draw(st.lists(crossing_objects(ego_start[:2]), min_size=1, max_size=2))]
    return base.replace(**overrides)


@st.composite
def actions(draw: st.DrawFn, scenario: Scenario) -> Any:
    """One action in the action space, as any of the accepted types: float32, float64 or int
    arrays, lists or tuples; often at the limits (float32-rounded limits included)."""
    ego = scenario.ego
    v = draw(st.one_of(real(ego.v_min, ego.v_max), st.sampled_from((ego.v_min, ego.v_max, 0.0))))
    omega = draw(
        st.one_of(real(-ego.omega_max, ego.omega_max), st.sampled_from((-ego.omega_max, ego.omega_max)))
    )
    form = draw(st.sampled_from(("float32", "float64", "list", "tuple", "int")))
    if form == "float32":
        return np.array([v, omega], dtype=np.float32)
    if form == "float64":
        return np.array([v, omega])
    if form == "list":
        return [v, omega]
    if form == "tuple":
        return (np.float32(v), omega)
    return np.array([int(v), int(omega)])  # truncation toward 0 stays inside limits around 0


@st.composite
def observations(draw: st.DrawFn, scenario: Scenario) -> np.ndarray:
    """An observation the env could produce: the ego near the path with a last input within the
    limits, the object anywhere within 20 m, its measured inputs within the scenario's ranges."""
    s = scenario
    ego = s.ego
    lam = draw(real(-95.0, 0.0))
    px, py, pth = point(s.path, lam)
    offset = draw(real(-5.0, 5.0))
    pose = (px - math.sin(pth) * offset, py + math.cos(pth) * offset, pth + draw(real(-1.0, 1.0)))
    ego_input = (draw(real(ego.v_min, ego.v_max)), draw(real(-ego.omega_max, ego.omega_max)))
    v_lo, v_hi = s.uncertainty.velocity_bounds0
    measurement = (
        pose[0] + draw(real(-20.0, 20.0)),
        pose[1] + draw(real(-20.0, 20.0)),
        draw(real(-math.pi, math.pi)),
        draw(real(v_lo, v_hi)),
        draw(real(-0.5, 0.5)),
    )
    return observe(s.path, ego.v_ref, s.collision_distances, pose, ego_input, [measurement], 1).obs


@st.composite
def env_cases(draw: st.DrawFn, max_steps: int = 20) -> dict[str, Any]:
    """A scenario, the env's estimator and object motion, a seed and an action per step."""
    scenario = draw(scenarios(max_steps=max_steps, many=True))
    plan = draw(st.lists(actions(scenario), min_size=scenario.max_steps, max_size=scenario.max_steps))
    return {
        "scenario": scenario,
        "object_slots": len(scenario.objects) + draw(st.sampled_from((0, 0, 1))),
        "risk_estimator": draw(st.sampled_from(ESTIMATOR_NAMES)),
        "object_motion": draw(st.sampled_from(OBJECT_MOTIONS)),
        "seed": draw(st.integers(0, 2**32 - 1)),
        "actions": plan,
    }


# ---------------------------------------------------------------- env invariants
def make_env(case: dict[str, Any], **kwargs: Any) -> RiskCrossingEnv:
    return RiskCrossingEnv(
        scenario=case["scenario"],
        risk_estimator=case["risk_estimator"],
        object_motion=case["object_motion"],
        object_slots=case.get("object_slots"),
        **kwargs,
    )


def check_step(env: RiskCrossingEnv, obs: np.ndarray, info: dict[str, Any]) -> None:
    """The invariants of one step's observation and info (also those of reset)."""
    s = env.scenario
    assert obs.dtype == np.float32 and obs.shape == (ob.size(env.object_slots),)
    assert env.observation_space.contains(obs), obs
    risk, terms = info["risk"], info["risk_terms"]
    assert math.isfinite(risk) and risk >= 0.0, risk
    assert terms.shape == (len(env.base_scenario.objects),) and np.all(terms >= 0.0)
    assert risk == pytest.approx(math.fsum(terms), rel=1e-12, abs=1e-300)
    assert info["cost"] == risk
    assert info["risk_violation"] == (risk > s.risk_tolerance)
    ego, objects = info["ego"], info["objects"][info["present"]]
    np.testing.assert_array_equal(info["object"], objects[0])
    gaps = np.hypot(ego[0] - objects[:, 0], ego[1] - objects[:, 1])
    assert info["distance"] == pytest.approx(gaps.min(), rel=1e-12, abs=1e-9)
    assert gaps[info["closest_object"]] == pytest.approx(gaps.min(), rel=1e-12, abs=1e-9)
    assert info["collision"] == bool(np.any(gaps <= np.array(s.collision_distances)))
    # the observation reports the true states
    parts = ob.split(obs, env.object_slots)
    assert parts.present.tolist() == [i < len(objects) for i in range(env.object_slots)]
    np.testing.assert_array_equal(obs[ob.EGO_POSE][:2], ego[:2].astype(np.float32))
    np.testing.assert_array_equal(parts.objects[parts.present][:, :2], objects[:, :2].astype(np.float32))
    assert obs[ob.EGO_INPUT][0] == np.float32(ego[3])
    np.testing.assert_array_equal(parts.objects[parts.present][:, 3], objects[:, 3].astype(np.float32))


def run_episode(env: RiskCrossingEnv, case: dict[str, Any], family: str = "env") -> list[tuple]:
    """Reset with the case's seed and step through its actions until the episode ends; checks
    every step and the error past the end. Returns the (obs, reward, terminated, truncated,
    info) of each step."""
    s = env.scenario
    obs, info = env.reset(seed=case["seed"])
    check_step(env, obs, info)
    assert info["risk"] == 0.0
    steps = []
    for k, action in enumerate(case["actions"]):
        obs, reward, terminated, truncated, info = env.step(action)
        FUZZED[family] += 1
        check_step(env, obs, info)
        assert reward == sum(info["rewards"].values())
        assert info["rewards"]["path_error"] == pytest.approx(-np.linalg.norm(info["path_error"]))
        assert terminated == (info["collision"] or info["lambda"] >= s.path.lambda_goal)
        assert truncated == (k + 1 >= s.max_steps)
        assert info["is_success"] == (info["lambda"] >= 0.0 and not info["collision"])
        steps.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            with pytest.raises(gym.error.ResetNeeded, match="the episode has ended"):
                env.step(action)
            break
    return steps


def same_steps(a: list[tuple], b: list[tuple]) -> None:
    assert len(a) == len(b)
    for (obs_a, *rest_a, info_a), (obs_b, *rest_b, info_b) in zip(a, b, strict=True):
        assert obs_a.tobytes() == obs_b.tobytes()
        assert rest_a == rest_b
        assert info_a.keys() == info_b.keys()
        for key in info_a:
            np.testing.assert_array_equal(info_a[key], info_b[key], err_msg=key)


def env_invariants(case: dict[str, Any]) -> None:
    run_episode(make_env(case), case)


def same_seed_same_trajectory(case: dict[str, Any]) -> None:
    first = make_env(case, randomize=True)
    again = run_episode(first, case, "env, same seed")
    fresh = run_episode(make_env(case, randomize=True), case, "env, same seed")
    same_steps(run_episode(first, case, "env, same seed"), again)  # the same env, the same seed
    same_steps(fresh, again)


test_env_invariants = fuzz(60)(given(case=env_cases())(env_invariants))
test_same_seed_same_trajectory = fuzz(12)(given(case=env_cases(max_steps=10))(same_seed_same_trajectory))
test_env_invariants_long = pytest.mark.slow(fuzz(1000)(given(case=env_cases(max_steps=60))(env_invariants)))
test_same_seed_same_trajectory_long = pytest.mark.slow(
    fuzz(100)(given(case=env_cases(max_steps=40))(same_seed_same_trajectory))
)


# ---------------------------------------------------------------- the batched env
def batched_invariants(case: dict[str, Any], num_envs: int, mode: str) -> None:
    s = case["scenario"]
    env = gym.make_vec(
        ENV_ID,
        num_envs=num_envs,
        scenario=s,
        risk_estimator=case["risk_estimator"],
        object_motion=case["object_motion"],
        object_slots=case["object_slots"],
        autoreset_mode=mode,
    )
    obs, _ = env.reset(seed=case["seed"])
    assert env.observation_space.contains(obs)
    rng = np.random.default_rng(case["seed"])
    for action in case["actions"]:
        batch = np.stack([np.asarray(action, dtype=np.float32)] * num_envs)
        batch[rng.random(num_envs) < 0.5] = np.asarray(case["actions"][0], dtype=np.float32)
        obs, rewards, terminated, truncated, info = env.step(batch)
        FUZZED["batched env"] += int(num_envs)
        assert env.observation_space.contains(obs), obs
        risk = info["risk"]
        assert np.all(np.isfinite(risk)) and np.all(risk >= 0.0)
        np.testing.assert_array_equal(info["cost"], risk)
        np.testing.assert_array_equal(info["risk_violation"], risk > s.risk_tolerance)
        np.testing.assert_allclose(info["risk_terms"].sum(axis=1), risk, rtol=1e-12, atol=1e-300)
        ego, objects = info["ego"], info["objects"]
        gaps = np.hypot(ego[:, None, 0] - objects[:, :, 0], ego[:, None, 1] - objects[:, :, 1])
        np.testing.assert_allclose(info["distance"], gaps.min(axis=1), rtol=1e-12, atol=1e-9)
        np.testing.assert_array_equal(
            info["collision"], np.any(gaps <= np.array(s.collision_distances), axis=1)
        )
        assert np.all(np.isfinite(rewards))
    env.close()


@fuzz(15)
@given(
    case=env_cases(max_steps=12),
    num_envs=integral(1, 4),
    mode=st.sampled_from(("next_step", "same_step")),
)
def test_batched_env_invariants(case, num_envs, mode):
    batched_invariants(case, num_envs, mode)


@pytest.mark.slow
@fuzz(60)
@given(
    case=env_cases(max_steps=60),
    num_envs=integral(1, 32),
    mode=st.sampled_from(("next_step", "same_step")),
)
def test_batched_env_invariants_long(case, num_envs, mode):
    batched_invariants(case, num_envs, mode)


# ---------------------------------------------------------------- scenarios up to the bounds
FIELD_NAMES = tuple(attr if part is None else f"{part}.{attr}" for part, attr in OVERRIDES.values())
"""How errors name the scenario's fields: ``ego.start``, ``object.speed``, ``max_steps``, ..."""


def magnitude(low_exp: float, high_exp: float) -> st.SearchStrategy[float]:
    """Log-uniform magnitudes 10^low_exp .. 10^high_exp, either sign."""
    return st.tuples(real(low_exp, high_exp), st.sampled_from((-1.0, 1.0))).map(lambda t: t[1] * 10 ** t[0])


@st.composite
def extreme_cases(draw: st.DrawFn) -> dict[str, Any]:
    """Scenarios around the observation bounds (positions to 1.2e5 m, speeds and turn rates to
    1.5e3): about half of them are rejected."""
    v_max = 10 ** draw(real(0.0, 3.1))
    v_min = -(10 ** draw(real(-1.0, 3.1)))
    speed_bound = 10 ** draw(real(0.0, 3.2))
    overrides = {
        "ego_start": (draw(magnitude(0, 5.1)), draw(magnitude(0, 5.1)), draw(real(-10.0, 10.0))),
        "goal": (draw(magnitude(0, 5.1)), draw(magnitude(0, 5.1)), draw(real(-3.0, 3.0))),
        "curvature": draw(st.sampled_from((0.0, 1e-4, -0.003))),
        "v_min": v_min,
        "v_max": v_max,
        "v_ref": draw(real(0.0, v_max)),
        "omega_max": 10 ** draw(real(-1.0, 3.1)),
        "object_start": (draw(magnitude(0, 5.1)), draw(magnitude(0, 5.1)), draw(real(-10.0, 10.0))),
        "velocity_bounds0": (-speed_bound, speed_bound),
        "object_speed": draw(real(-speed_bound, speed_bound)),
        "object_turn_rate": draw(magnitude(-3, 3.2)),
        "box_growth": (draw(real(0.0, 50.0)),) * 3,
        "dt": 10 ** draw(real(-1.5, 0.5)),
        "max_steps": draw(integral(1, 12)),
    }
    return {
        "overrides": overrides,
        "risk_estimator": draw(st.sampled_from(ESTIMATOR_NAMES)),
        "object_motion": draw(st.sampled_from(OBJECT_MOTIONS)),
        "seed": draw(st.integers(0, 2**32 - 1)),
        "corners": draw(st.lists(st.tuples(st.booleans(), st.booleans()), min_size=12, max_size=12)),
    }


@fuzz(50)
@given(case=extreme_cases())
def test_accepted_scenarios_keep_observations_in_the_box(case):
    try:
        scenario = Scenario.preset("low", **case["overrides"])
    except ValueError as error:
        FUZZED["rejected scenarios"] += 1
        # the scenario's own checks, naming a field: never an error from deeper down
        assert any(name in str(error) for name in FIELD_NAMES), error
        return
    env = RiskCrossingEnv(
        scenario=scenario, risk_estimator=case["risk_estimator"], object_motion=case["object_motion"]
    )
    low, high = env.action_space.low, env.action_space.high
    plan = [np.where(corner, high, low) for corner in case["corners"][: scenario.max_steps]]
    with np.errstate(all="ignore"):  # far-off states may underflow inside the risk kernels
        run_episode(env, {"seed": case["seed"], "actions": plan}, "env, extreme scenarios")


# ---------------------------------------------------------------- agents
def check_agent_action(scenario: Scenario, action: np.ndarray, obs: np.ndarray) -> None:
    """Finite, float32 (2,), inside the action Box and within the rate limits from the last input."""
    ego, dt = scenario.ego, scenario.dt
    assert action.dtype == np.float32 and action.shape == (2,)
    assert np.all(np.isfinite(action)), action
    box = gym.spaces.Box(
        np.array([ego.v_min, -ego.omega_max], dtype=np.float32),
        np.array([ego.v_max, ego.omega_max], dtype=np.float32),
    )
    assert box.contains(action), action
    v_last, w_last = (float(x) for x in obs[ob.EGO_INPUT])
    assert abs(float(action[0]) - v_last) <= ego.accel_max * dt + 1e-5, (action, v_last)
    assert abs(float(action[1]) - w_last) <= ego.omega_rate_max * dt + 1e-5, (action, w_last)


AGENTS = {
    "RMPC": lambda s: RMPC(s, max_solve_time=math.inf),
    "SMPC": lambda s: SMPC(s, risk="exact", max_solve_time=math.inf),
}
"""No wall-time cap: the actions' limits hold for every plan and every fallback, and a busy machine
must not decide which of them acts (the cap's own tests are in tests/test_cap.py)."""


def agents_in_closed_loop(name: str, scenario: Scenario, seed: int) -> None:
    agent = AGENTS[name](scenario)
    assert isinstance(agent, Policy)
    env = RiskCrossingEnv(scenario=scenario, object_motion="sampled")
    obs, _ = env.reset(seed=seed)
    start = True
    for _ in range(scenario.max_steps):
        action, state = agent.predict(obs, episode_start=np.array([start]))
        FUZZED["agent decisions"] += 1
        start = False
        assert state is None
        check_agent_action(scenario, action, obs)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break


@st.composite
def agent_observations(draw: st.DrawFn) -> tuple[Scenario, list[np.ndarray]]:
    scenario = draw(scenarios(max_steps=1, horizon=3))
    return scenario, draw(st.lists(observations(scenario), min_size=1, max_size=3))


def agents_on_observations(name: str, case: tuple[Scenario, list[np.ndarray]]) -> None:
    scenario, batch = case
    agent = AGENTS[name](scenario)
    actions, _ = agent.predict(np.stack(batch), episode_start=np.ones(len(batch), dtype=bool))
    FUZZED["agent decisions"] += len(batch)
    assert actions.shape == (len(batch), 2)
    for action, obs in zip(actions, batch, strict=True):
        check_agent_action(scenario, action, obs)
    single, _ = agent.predict(batch[0], episode_start=True)
    check_agent_action(scenario, single, batch[0])


AGENT_NAMES = st.sampled_from(sorted(AGENTS))
CLOSED_LOOPS = given(name=AGENT_NAMES, scenario=scenarios(max_steps=6, horizon=3), seed=st.integers(0, 2**16))
# every example builds its agent's solvers (its scenario's structure is fuzzed too): a few here,
# 40 each in the slow tests below
test_agents_act_within_limits_in_closed_loop = fuzz(4)(CLOSED_LOOPS(agents_in_closed_loop))
test_agents_act_within_limits_on_fuzzed_observations = fuzz(6)(
    given(name=AGENT_NAMES, case=agent_observations())(agents_on_observations)
)
test_agents_act_within_limits_in_closed_loop_long = pytest.mark.slow(
    fuzz(40)(CLOSED_LOOPS(agents_in_closed_loop))
)
test_agents_act_within_limits_on_fuzzed_observations_long = pytest.mark.slow(
    fuzz(40)(given(name=AGENT_NAMES, case=agent_observations())(agents_on_observations))
)
