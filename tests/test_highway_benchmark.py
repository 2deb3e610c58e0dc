"""The intersection benchmarks: highway-env's options reach the env, every column is recorded,
deadlocks are counted, bad inputs fail before any episode, the frontier and the modes are drawn.

Runs are tiny (one episode of 1.5 s, one object slot, the paper's predictor); the MPCs' wall-time
cap is theirs, but no assertion depends on what it cut short."""

from __future__ import annotations

import contextlib
import io
import math
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("highway_env")

from benchmarks import highway_frontier, highway_intersection  # noqa: E402
from benchmarks.highway_agents import HighwayAgent, make_driver, resolve  # noqa: E402
from benchmarks.highway_episodes import (  # noqa: E402
    ENV_DEFAULTS,
    deadlocked,
    jammed,
    make_env,
    standing_inside,
    wrecked,
)
from benchmarks.highway_frontier import beats, draw_frontier  # noqa: E402
from benchmarks.sampled_rows import wilson  # noqa: E402

TINY = ["--episodes", "1", "--duration", "1.5", "--initial-vehicles", "3", "--slots", "1"]
TINY += ["--predictor", "constant", "--workers", "1", "--max-solve-time", "inf"]
"""One 1.5 s episode (3 steps) per agent, one object slot, the paper's predictor, no wall-time cap
(as the committed runs; a busy machine must not decide the fallbacks)."""


# ------------------------------------------------------------------------------------- options
def test_the_defaults_are_highway_envs_own():
    import gymnasium as gym

    for version in highway_intersection.ENVS:
        config = gym.make(version).unwrapped.config
        assert {k: config[k] for k in ENV_DEFAULTS} == ENV_DEFAULTS
    args = highway_intersection.parse_args([])
    assert (args.duration, args.spawn_probability, args.initial_vehicles) == (13.0, 0.6, 10)
    assert args.predictor == ["lane"] and args.budget == 0.05


def test_duration_spawn_probability_and_initial_vehicles_reach_highway_env():
    counts = []
    for n in (0, 10):
        argv = ["--duration", "2", "--spawn-probability", "0.3", "--initial-vehicles", str(n)]
        env = make_env(highway_intersection.parse_args(argv), "constant")
        config = env.unwrapped.config
        assert (config["duration"], config["spawn_probability"], config["initial_vehicle_count"]) == (
            2.0,
            0.3,
            n,
        )
        env.reset(seed=0)
        counts.append(len(env.unwrapped.road.vehicles))
    assert counts[0] < counts[1]


def test_what_each_agent_name_means_at_the_intersection():
    smpc = resolve("smpc", "probability", 0.05)
    assert smpc == HighwayAgent("smpc", "exact", "probability", math.inf, 0.05)
    assert smpc.name == "smpc:exact:budget=0.05"
    assert smpc.label == "SMPC (exact risk), probability severity, episode budget 0.05, no per-step bound"
    assert resolve("smpc:budget=0.02", "probability", 0.05).budget == 0.02
    step = resolve("smpc:probability:0.01", "probability", 0.05)
    assert (step.tolerance, step.budget, step.name) == (0.01, None, "smpc:exact:probability:0.01")
    both = resolve("smpc:injury:0.001:budget=0.01", "probability", 0.05)
    assert both.label == "SMPC (exact risk), injury severity, epsilon 0.001 per step, episode budget 0.01"
    assert resolve(smpc.name, "probability", 0.05) == smpc  # the printed name reads back
    assert resolve("rmpc", "probability", 0.05).label == "RMPC (worst case risk)"
    with pytest.raises(ValueError, match="budget 2 exceeds 1"):
        resolve("smpc:budget=2", "probability", 0.05)
    assert resolve("smpc:budget=2", "injury", 0.05).budget == 2.0


def test_each_mpc_runs_with_each_predictor_the_idm_once():
    runs = highway_intersection.plan_runs(
        ["rmpc:worst_case", "idm", "smpc:exact:budget=0.05", "hindsight"], ["lane", "constant"]
    )
    assert runs[-1] == ("hindsight", "")  # a reference driver: no predictor
    assert runs[:-1] == [
        ("rmpc:worst_case", "lane"),
        ("rmpc:worst_case", "constant"),
        ("idm", ""),
        ("smpc:exact:budget=0.05", "lane"),
        ("smpc:exact:budget=0.05", "constant"),
    ]
    assert highway_frontier.parse_args([]).predictor == ["lane", "constant"]


def test_the_options_reach_the_mpcs():
    argv = ["--mode-threshold", "0.2", "--budget-share", "0.25", "--max-solve-time", "inf", "--slots", "2"]
    args = highway_intersection.parse_args(argv)
    env = make_env(args, "constant")
    smpc = make_driver(resolve("smpc", "probability", 0.03), env, args, "constant")
    assert smpc.make_agent.factory.keywords == {
        "risk": "exact",
        "mode_threshold": 0.2,
        "max_solve_time": math.inf,
        "risk_tolerance": math.inf,
        "risk_budget": 0.03,
        "budget_share": 0.25,
    }
    assert smpc.slots == 2 and smpc.base_scenario.severity == "probability"
    rmpc = make_driver(resolve("rmpc", "probability", 0.03), env, args, "constant")
    assert "risk_budget" not in rmpc.make_agent.factory.keywords
    lane = make_driver(resolve("rmpc", "probability", 0.03), env, args, "lane")
    assert lane.predictor is None  # built on the road network at the first episode


def test_the_egos_speed_and_acceleration_reach_the_mpcs_and_the_gate():
    """``--v-ref`` and ``--ego-accel`` set the adapter's scenario (v_max rises to a faster v_ref), which
    the gate reads for its crossing; the defaults keep the adapter's 8 m/s and the paper's 3 m/s^2."""
    args = highway_intersection.parse_args(["--v-ref", "9.5", "--ego-accel", "5"])
    env = make_env(args, "lane")
    driver = make_driver(resolve("rmpc", "probability", 0.05), env, args, "lane")
    env.reset(seed=0)
    driver.reset()
    ego = driver.base_scenario.ego
    assert (ego.v_ref, ego.v_max, ego.accel_max) == (9.5, 10.0, 5.0)
    assert driver.gate.accel == 5.0 and driver.gate.speed_cap <= 9.5
    rmpc = resolve("rmpc", "probability", 0.05)
    plain = make_driver(rmpc, env, highway_intersection.parse_args([]), "lane").base_scenario.ego
    assert (plain.v_ref, plain.accel_max) == (8.0, 3.0)
    fast = highway_intersection.parse_args(["--v-ref", "12"])
    assert make_driver(rmpc, env, fast, "lane").base_scenario.ego.v_max == 12.0
    for bad in (["--v-ref", "0"], ["--ego-accel", "nan"]):
        with pytest.raises(SystemExit):
            highway_intersection.parse_args(bad)


def test_lane_pieces_reach_the_mpcs_predictor_and_size_their_mode_slots():
    args = highway_intersection.parse_args(["--lane-pieces", "3", "--max-solve-time", "inf"])
    env = make_env(args, "lane")
    driver = make_driver(resolve("rmpc", "probability", 0.05), env, args, "lane")
    driver.warm_up = False  # one step: its own NLPs only (the warm-up is tests/test_warmup.py's)
    obs, _ = env.reset(seed=0)
    driver.reset()
    driver.predict(obs)
    assert driver.predictor.pieces == 3 and driver.predictor.max_modes == 9
    agent = driver._agent_for(driver.lane)
    assert agent._slots.modes == 9  # one row per piece of each route
    assert make_driver(resolve("rmpc", "probability", 0.05), env, args, "constant").predictor is None


def test_the_adapter_sums_what_its_lane_agents_spent():
    from agents import RMPC
    from risk_env.highway import IntersectionAdapter, make_intersection_env

    adapter = IntersectionAdapter(make_intersection_env(), RMPC, predictor="constant")
    assert adapter.spent_risk() == 0.0
    adapter._agents = {
        "approach": SimpleNamespace(spent_risk=lambda: 0.01),
        "turn": SimpleNamespace(spent_risk=lambda: 0.02),
        "rmpc": object(),
    }
    assert adapter.spent_risk() == pytest.approx(0.03)


# ------------------------------------------------------------------------------------- columns
def test_an_episode_records_every_column(tmp_path):
    summary = highway_intersection.main([*TINY, "--agents", "rmpc,smpc,idm", "--out", str(tmp_path)])
    rows = {s["agent"]: s for s in summary}
    assert list(rows) == ["rmpc:worst_case", "smpc:exact:budget=0.05", "idm"]
    for s in summary:
        assert s["episodes"] == 1 and s["steps"] == 3  # 1.5 s of 0.5 s steps
        assert s["collision"] + s["goal"] + s["timeout"] == 1
        assert s["ego_into_vehicle"] + s["vehicle_into_ego"] == s["collision"]
        assert s["deadlock"] == 0  # shorter than the 10 s a deadlock needs
        assert s["off_road"] == 0
        for key in ("collision", "goal", "deadlock", "off_road"):
            assert (s[f"{key}_ci_low"], s[f"{key}_ci_high"]) == pytest.approx(wilson(s[key], 1))
    for name in ("rmpc:worst_case", "smpc:exact:budget=0.05"):
        s = rows[name]
        assert s["predictor"] == "constant" and s["mpc_steps"] == 3
        assert 0 < s["cpu_ms_median"] <= s["cpu_ms_p95"] <= s["cpu_ms_max"]
        assert 0 < s["solve_ms_median"] <= s["solve_ms_max"]
        assert s["fallback_share"] == pytest.approx(s["fallbacks"] / 3)
        assert s["build_steps"] == 0  # the paper's predictor: every NLP is built with the agent, untimed
    smpc = rows["smpc:exact:budget=0.05"]
    assert smpc["budget"] == 0.05 and 0.0 <= smpc["spent_mean"] <= smpc["spent_max"]
    assert smpc["over_budget"] == int(smpc["spent_max"] > 0.05)
    assert rows["rmpc:worst_case"]["budget"] == "" and rows["idm"]["predictor"] == ""
    assert np.isnan(rows["idm"]["cpu_ms_median"])
    text = (tmp_path / "intersection.md").read_text()
    assert "episode budget 0.05, no per-step bound" in text and "solve CPU ms median / p95 / max" in text
    header = "| timeouts jammed (of which deadlocks) | behind a wreck (of which deadlocks) | left the road |"
    assert header in text
    assert "duration 1.5 s" in text and s["jammed"] == 0 == s["deadlock_jammed"]
    assert s["wrecked"] == 0 == s["deadlock_wrecked"]
    episodes = (tmp_path / "intersection_episodes.csv").read_text().splitlines()
    assert len(episodes) == 4 and "deadlock,jammed,wrecked" in episodes[0] and "cpu_ms_median" in episodes[0]
    assert "steps that built an NLP" in text


def test_a_step_that_builds_an_nlp_is_timed_apart_and_leaving_the_road_counts(monkeypatch):
    from collections import OrderedDict

    from agents.mpc.nlp import solver
    from benchmarks.highway_episodes import run_episode

    cache: OrderedDict = OrderedDict()
    monkeypatch.setattr(solver, "_SOLVER_CACHE", cache)

    class Driver:  # builds its agent at step 1 (untimed), an NLP of a new size at step 2
        destination, last_objects = "o1", np.zeros((0, 5))
        make_agent = SimpleNamespace(built={"the agent's own"})
        last_solves = [SimpleNamespace(solve_time=0.02, cpu_time=0.01)]
        steps = 0

        def predict(self, observation):
            self.steps += 1
            cache.setdefault({1: "the agent's own", 2: "a new size"}.get(self.steps, "the agent's own"))
            if self.steps == 3:  # and then leaves the road
                env.unwrapped.vehicle.position = np.array([60.0, 60.0])
            return np.zeros(2, dtype=np.float32), None

    args = highway_intersection.parse_args(["--duration", "1.5", "--initial-vehicles", "0"])
    env = make_env(args, "constant")
    row = run_episode(Driver(), env, seed=0, slots=1)
    assert row["built"].tolist() == [False, True, False]
    assert row["cpu_times"].tolist() == [0.01] * 3
    assert row["off_road"] and row["off_road_steps"] == 1


def test_deadlocks_from_a_synthetic_record():
    times = np.arange(0.0, 13.5, 0.5)

    def stopped_from(t: float) -> np.ndarray:
        return np.where(times < t, 8.0, 0.02)

    assert deadlocked(times, stopped_from(2.5), collision=False, goal=False)
    assert deadlocked(times, stopped_from(3.0), collision=False, goal=False)  # exactly the last 10 s
    assert not deadlocked(times, stopped_from(3.5), collision=False, goal=False)  # 9.5 s
    assert not deadlocked(times, stopped_from(0.0), collision=True, goal=False)
    assert not deadlocked(times, stopped_from(0.0), collision=False, goal=True)
    assert not deadlocked(times[:17], stopped_from(0.0)[:17], collision=False, goal=False)  # 8 s long
    blip = stopped_from(0.0)
    blip[times == 8.0] = 0.2  # it crept forward once
    assert not deadlocked(times, blip, collision=False, goal=False)
    assert deadlocked(times, -stopped_from(1.0), collision=False, goal=False)  # rolling back slowly


def test_a_jam_is_a_vehicle_standing_in_the_junction_for_the_last_ten_seconds():
    """standing_inside keeps, step by step, since when each other vehicle has stood on a junction lane
    (from an ``ir*`` node); it drops one that moves or leaves; jammed asks for 10 s of it."""
    from types import SimpleNamespace as Car

    ego = Car(lane_index=("ir0", "il1", 0), speed=0.0)
    inside = Car(lane_index=("ir1", "il3", 0), speed=0.0)
    waiting = Car(lane_index=("o2", "ir2", 0), speed=0.0)  # stopped before the junction: no jam
    base = Car(vehicle=ego, road=Car(vehicles=[ego, inside, waiting]), time=2.0)
    since = standing_inside(base, {})
    assert since == {id(inside): 2.0}  # the ego and the one outside are not counted
    base.time = 12.0
    since = standing_inside(base, since)
    assert since == {id(inside): 2.0}
    assert jammed(since, 12.0, collision=False, goal=False)
    assert not jammed(since, 11.5, collision=False, goal=False)  # 9.5 s
    assert not jammed(since, 12.0, collision=True, goal=False)
    assert not jammed(since, 12.0, collision=False, goal=True)
    inside.speed = -0.3  # rolling back: moving
    assert standing_inside(base, since) == {}


def test_a_wreck_on_the_egos_way_is_counted_and_an_episode_from_before_the_count_is_unknown():
    """wrecked: a crashed vehicle other than the ego whose centre lies within 2.5 m of the ego's route
    ahead of it, at a timeout; not one beside the way or behind the ego, not the ego, not after a
    collision or the goal. Rows without the field (chunks resumed from before the count) leave the
    summary's count unknown ("n/a"), never 0."""
    from types import SimpleNamespace as Car

    from benchmarks.highway_tables import _wrecks
    from risk_env.highway import make_intersection_env
    from risk_env.highway.route import RoutePath

    env = make_intersection_env()
    env.reset(seed=0)
    base = env.unwrapped
    destination = base.config["destination"]
    route = RoutePath.of_vehicle(base.road.network, base.vehicle, destination)
    start = route.progress(0, *base.vehicle.position)
    base.road.vehicles[:] = [base.vehicle]
    on_way = Car(position=route.position(start + 30.0) + np.array([1.5, 1.5]) / np.sqrt(2.0), crashed=True)
    behind = Car(position=route.position(max(start - 8.0, 0.0)), crashed=True)
    assert start - 8.0 > 3.0  # the ego starts more than a car's length into its lane
    assert not wrecked(base, destination, collision=False, goal=False)
    base.road.vehicles.append(behind)
    assert not wrecked(base, destination, collision=False, goal=False)
    base.road.vehicles.append(on_way)
    assert wrecked(base, destination, collision=False, goal=False)
    assert not wrecked(base, destination, collision=True, goal=False)
    assert not wrecked(base, destination, collision=False, goal=True)
    on_way.crashed = False  # standing, not crashed: a jam, not a wreck
    assert not wrecked(base, destination, collision=False, goal=False)
    on_way.crashed = True
    along = route.position(start + 31.0) - route.position(start + 29.0)
    beside = route.position(start + 30.0) + 3.5 * np.array([-along[1], along[0]]) / np.hypot(*along)
    on_way.position = beside  # 3.5 m to the side: the next lane
    assert not wrecked(base, destination, collision=False, goal=False)
    base.vehicle.crashed = True  # the ego is never its own wreck
    assert not wrecked(base, destination, collision=False, goal=False)
    assert _wrecks({"wrecked": 3, "deadlock_wrecked": 2}) == "3 (2)"
    assert _wrecks({"wrecked": None, "deadlock_wrecked": None}) == "n/a"


# ------------------------------------------------------------------------------------ bad input
def _fails(module, argv: list[str], flag: str, message: str = "") -> None:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        with pytest.raises(SystemExit) as stop:
            module.main(argv)
    assert stop.value.code not in (0, None)
    assert flag in err.getvalue() and message in err.getvalue(), err.getvalue()


@pytest.mark.parametrize(
    ("argv", "flag", "message"),
    [
        (["--budget", "-0.1"], "--budget", "finite number >= 0"),
        (["--budget", "nan"], "--budget", "finite number >= 0"),
        (["--budget", "1.5"], "--budget", "exceeds 1"),
        (["--agents", "smpc:budget=2"], "--agents", "exceeds 1"),
        (["--agents", "smpc:budget=nan"], "--agents", "must be finite"),
        (["--agents", "smpc:probability:0.01:budget=-1"], "--agents", "must be finite and >= 0"),
        (["--duration", "0"], "--duration", "finite number > 0"),
        (["--duration", "nan"], "--duration", ""),
        (["--duration", "inf"], "--duration", ""),
        (["--duration", "0.2"], "--duration", "shorter than one step"),
        (["--spawn-probability", "1.5"], "--spawn-probability", "[0, 1]"),
        (["--spawn-probability", "-0.1"], "--spawn-probability", ""),
        (["--spawn-probability", "nan"], "--spawn-probability", ""),
        (["--initial-vehicles", "-1"], "--initial-vehicles", ""),
        (["--mode-threshold", "1.5"], "--mode-threshold", "[0, 1]"),
        (["--mode-threshold", "-0.1"], "--mode-threshold", ""),
        (["--lane-pieces", "0"], "--lane-pieces", ""),
        (["--budget-share", "0"], "--budget-share", "(0, 1]"),
        (["--predictor", "oracle"], "--predictor", "unknown predictor 'oracle'"),
        (["--predictor", "lane,lane"], "--predictor", "named twice"),
        (["--agents", "smpc,smpc:budget=0.05"], "--agents", "named twice"),
        (["--tolerance", "0.01"], "--tolerance", "smpc:probability:0.01"),
        (["--gate-passage"], "--gate-passage", "needs --predictor lane+interval"),
        (
            ["--gate-judge", "rollout", "--predictor", "lane+interval,constant"],
            "--gate-judge",
            "got constant",
        ),
    ],
)
@pytest.mark.parametrize("module", [highway_intersection, highway_frontier], ids=["intersection", "frontier"])
def test_bad_input_fails_naming_it_before_any_episode(module, argv, flag, message, tmp_path):
    out = tmp_path / "out"
    _fails(module, [*argv, "--out", str(out)], flag, message)
    assert not out.exists()


def test_a_budget_above_one_is_fine_in_other_severities():
    args = highway_intersection.parse_args(["--budget", "3", "--severity", "injury"])
    assert args.agents == ["rmpc:worst_case", "smpc:exact:budget=3", "idm"]


# ------------------------------------------------------------------------------------ the frontier
def _row(agent: str, predictor: str, collisions: int, goals: int, n: int = 100) -> dict:
    row = {"agent": agent, "predictor": predictor}
    for key, k in (("collision", collisions), ("goal", goals)):
        lo, hi = wilson(k, n)
        row |= {f"{key}_rate": k / n, f"{key}_ci_low": lo, f"{key}_ci_high": hi}
    return row


def test_the_frontier_figure_marks_every_agent(tmp_path):
    from PIL import Image

    summary = [_row("rmpc:worst_case", "lane", 0, 50), _row("rmpc:worst_case", "constant", 0, 28)]
    for b, c, g in ((0.01, 2, 55), (0.02, 3, 60), (0.05, 5, 66), (0.1, 8, 70)):
        summary += [
            _row(f"smpc:exact:budget={b}", "lane", c, g),
            _row(f"smpc:exact:budget={b}", "constant", 3 * c, g - 20),
        ]
    summary += [_row("smpc:exact:probability:0.01", "lane", 20, 60), _row("idm", "", 17, 44)]
    idm = summary[-1]
    assert beats(summary[2], idm) and not beats(summary[1], idm) and not beats(summary[-2], idm)
    path = draw_frontier(summary, tmp_path / "frontier.png", "a test")
    with Image.open(path) as image:
        pixels = np.asarray(image.convert("RGB")).reshape(-1, 3)
    for colour in ((31, 119, 180), (255, 127, 14), (0, 0, 0)):  # RMPC, SMPC, IDM
        assert np.any(np.all(pixels == colour, axis=1)), colour


def test_the_frontier_from_a_tiny_run(tmp_path):
    from PIL import Image

    summary = highway_frontier.main([*TINY, "--agents", "rmpc,idm", "--out", str(tmp_path)])
    assert [s["agent"] for s in summary] == ["rmpc:worst_case", "idm"]
    for name in highway_frontier.FILES:
        assert (tmp_path / name).stat().st_size > 0
    with Image.open(tmp_path / "frontier.png") as image:
        assert image.size == (1260, 720)  # the legend beside the plot
    assert "- `rmpc:worst_case (constant)`: " in (tmp_path / "frontier.md").read_text()
    assert (tmp_path / "frontier.manifest.json").exists()


# ------------------------------------------------------------------------------------ the modes
def _mode(weight: float, x0: float, frame: float) -> SimpleNamespace:
    n = np.arange(3.0)
    beliefs = SimpleNamespace(
        x=x0 + 3 * n, y=np.zeros(3), half_x=np.full(3, 4.0), half_y=np.full(3, 1.0), frame=np.full(3, frame)
    )
    return SimpleNamespace(weight=weight, beliefs=beliefs)


def test_modes_are_drawn_in_their_frame_with_their_weight_as_opacity():
    from risk_env.highway import graphics as G
    from risk_env.highway import make_intersection_env

    np.testing.assert_allclose(
        G.box_corners(1.0, 2.0, 2.0, 1.0, math.pi / 2), [[0, 4], [0, 0], [2, 0], [2, 4]], atol=1e-12
    )
    env = make_intersection_env()
    env.reset(seed=0)
    plain = G.render_scene(env, centre=(0.0, 0.0), scaling=5.0)

    def changed(*modes: SimpleNamespace) -> np.ndarray:
        frame = G.render_scene(
            env, centre=(0.0, 0.0), scaling=5.0, mixtures=[SimpleNamespace(modes=list(modes))]
        )
        return np.abs(frame.astype(int) - plain).sum(axis=-1)

    likely, unlikely = changed(_mode(0.9, 0.0, 0.0)), changed(_mode(0.1, 0.0, 0.0))
    assert likely.max() > 2 * unlikely.max() > 0  # the weight is the opacity
    turned = changed(_mode(0.9, 0.0, math.pi / 2))
    assert not np.array_equal(turned > 0, likely > 0)  # the boxes turned with their frame
    assert changed(_mode(0.0, 40.0, 0.0)).max() > 0  # a mode of weight 0 stays visible (MIN_OPACITY)
    from risk_env.highway import highway_scenario
    from risk_env.prediction.predictors import ConstantPredictor

    mixture = ConstantPredictor(highway_scenario(env)).predict([0.0, 0.0, 0.3, 5.0, 0.0], 3)
    assert changed(*mixture.modes).max() > 0  # a predictor's own mixture (Beliefs with their frame)


@pytest.mark.slow
def test_the_intersection_gif_draws_every_vehicles_modes(tmp_path):
    from PIL import Image

    from benchmarks import highway_render

    argv = ["--max-steps", "1", "--intersection", "--predictor", "constant", "--intersection-duration", "1"]
    highway_render.main([*argv, "--out", str(tmp_path)])
    gif = tmp_path / "intersection_rmpc_constant.gif"
    with Image.open(gif) as image:
        assert image.n_frames == 2
