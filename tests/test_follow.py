"""Road users ahead on the ego's route: boxes the ego follows (risk_env.highway.lanes.follow)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("highway_env")

from risk_env.highway import make_intersection_env  # noqa: E402
from risk_env.highway.gate import GatePredictor  # noqa: E402
from risk_env.highway.lanes.follow import Leaders, follow_leaders  # noqa: E402
from risk_env.highway.lanes.routes import Route  # noqa: E402
from risk_env.highway.route import RoutePath  # noqa: E402
from risk_env.prediction.belief import Belief  # noqa: E402
from risk_env.prediction.mixture import Mixture, Mode  # noqa: E402
from risk_env.prediction.predictors import Predictor  # noqa: E402

STEPS = 4


@pytest.fixture(scope="module")
def route() -> Route:
    """The ego's route of seed 0: its approach, its turn through the junction and its exit."""
    env = make_intersection_env()
    env.reset(seed=0)
    base = env.unwrapped
    path = RoutePath.of_vehicle(base.road.network, base.vehicle, base.config["destination"])
    return Route(base.road.network, path.lanes)


def car(route: Route, s: np.ndarray, r: float = 0.0, backwards: bool = False) -> Mode:
    """A mode whose mean drives at arc lengths ``s (STEPS + 1,)`` and offset ``r`` along ``route``
    (against it with ``backwards``), with the lane predictor's narrow box across."""
    xy = route.position(s, r)
    heading = route.heading(s) + (np.pi if backwards else 0.0)
    n = len(s)
    full = lambda value: np.full(n, float(value))  # noqa: E731
    belief = Belief(
        x=xy[:, 0], y=xy[:, 1], theta=heading, speed=full(5.0),
        sigma_x=full(0.5), sigma_y=full(0.2), sigma_v=full(0.5),
        half_x=full(3.0), half_y=full(1.5), v_lo=full(0.0), v_hi=full(10.0), frame=heading,
    )  # fmt: skip
    return Mode(1.0, belief, "along")


def test_locate_returns_the_arc_length_and_the_offset(route):
    s = np.array([5.0, 30.0, route.length - 5.0])
    for r in (0.0, 1.5, -1.0):
        found_s, found_r = route.locate_many(route.position(s, r))
        np.testing.assert_allclose(found_s, s, atol=0.05)
        np.testing.assert_allclose(found_r, r, atol=0.05)


def test_a_road_user_ahead_on_the_route_spans_the_corridor_and_no_other_does(route):
    """Ahead, in the lane, heading along: half width across at least |r| + corridor at n >= 1;
    behind the ego, heading against the route, or in another lane: the box as it was."""
    ego_s = 20.0
    ego = tuple(route.position(np.array(ego_s)).tolist())
    leaders = Leaders(route, ego, corridor=1.5)
    s = ego_s + np.linspace(6.0, 16.0, STEPS + 1)
    cases = {
        "ahead": car(route, s, r=0.3),
        "behind": car(route, s - 30.0, r=0.3),
        "oncoming": car(route, s, r=0.3, backwards=True),
        "beside": car(route, s, r=4.0),
    }
    out = follow_leaders([Mixture((mode,)) for mode in cases.values()], leaders)
    half = {name: np.asarray(m.modes[0].beliefs.half_y) for name, m in zip(cases, out, strict=True)}
    assert half["ahead"][0] == 1.5  # n = 0, the measurement: as it was
    np.testing.assert_allclose(half["ahead"][1:], 1.8, atol=0.05)  # |r| + corridor
    for name in ("behind", "oncoming", "beside"):
        np.testing.assert_array_equal(half[name], 1.5)
    # the rest of every belief is untouched
    for before, after in zip(cases.values(), out, strict=True):
        for field in dataclasses.fields(Belief):
            if field.name != "half_y":
                np.testing.assert_array_equal(
                    getattr(before.beliefs, field.name), getattr(after.modes[0].beliefs, field.name)
                )


def test_a_leader_the_ego_could_pass_beside_is_widened_to_the_corridors_edge(route):
    """A box narrower than the corridor (the ego could pass it at the corridor's edge) reaches across it."""
    ego_s = 10.0
    leaders = Leaders(route, tuple(route.position(np.array(ego_s)).tolist()), corridor=1.5)
    mode = car(route, ego_s + np.linspace(8.0, 12.0, STEPS + 1), r=-0.5)
    narrow = dataclasses.replace(mode.beliefs, half_y=np.full(STEPS + 1, 0.8))
    out = follow_leaders([Mixture((dataclasses.replace(mode, beliefs=narrow),))], leaders)
    np.testing.assert_allclose(np.asarray(out[0].modes[0].beliefs.half_y)[1:], 2.0, atol=0.05)


class Fixed(Predictor):
    """Every road user as one given mode."""

    name = "fixed"
    max_modes = 1

    def __init__(self, mode: Mode) -> None:
        self.mode = mode

    def predict(self, measurement, steps):
        return Mixture((self.mode,))


def test_the_gate_predictor_follows_leaders_only_when_told(route):
    ego_s = 20.0
    mode = car(route, ego_s + np.linspace(6.0, 16.0, STEPS + 1))
    narrow = dataclasses.replace(mode.beliefs, half_y=np.full(STEPS + 1, 0.5))
    wrapped = GatePredictor(Fixed(dataclasses.replace(mode, beliefs=narrow)))
    row = np.array([[0.0, 0.0, 0.0, 5.0, 0.0]])
    assert np.all(np.asarray(wrapped.predict_scene(row, STEPS)[0].modes[0].beliefs.half_y) == 0.5)
    wrapped.leaders = Leaders(route, tuple(route.position(np.array(ego_s)).tolist()), corridor=1.0)
    assert np.all(np.asarray(wrapped.predict_scene(row, STEPS)[0].modes[0].beliefs.half_y)[1:] >= 1.0)


def test_bad_leaders_are_named(route):
    with pytest.raises(TypeError, match="Leaders.route"):
        Leaders("o0>ir0", (0.0, 0.0), 1.0)
    with pytest.raises(ValueError, match="Leaders.corridor"):
        Leaders(route, (0.0, 0.0), -1.0)
    with pytest.raises(ValueError, match="Leaders.position"):
        Leaders(route, (np.nan, 0.0), 1.0)


def test_following_needs_a_predictor_of_the_lanes():
    from risk_env.highway import IntersectionAdapter
    from risk_env.highway.gate_judge import GateSettings

    with pytest.raises(ValueError, match="GateSettings.follow"):
        IntersectionAdapter(
            make_intersection_env(), object, gate=GateSettings(follow=True), predictor="constant"
        )


def test_the_adapter_hands_the_agents_predictor_the_ego_each_step():
    """With ``follow`` the agents' predictor gets the ego's route and position every step; without, none."""
    from risk_env.highway import IntersectionAdapter
    from risk_env.highway.gate_judge import GateSettings

    class Stub:
        def __init__(self, scenario, object_slots, predictor=None):
            self.predictor = predictor

        def predict(self, obs, episode_start=None, deterministic=True):
            return np.array([6.0, 0.0]), None

    for follow in (True, False):
        env = make_intersection_env()
        adapter = IntersectionAdapter(env, Stub, slots=3, gate=GateSettings(follow=follow), predictor="lane")
        obs, _ = env.reset(seed=1)
        adapter.reset()
        for _ in range(2):
            seen = env.unwrapped.vehicle.position.copy()  # where the ego is when the adapter acts
            obs, *_ = env.step(adapter.predict(obs)[0])
        leaders = adapter.gate.wrapper.leaders
        if not follow:
            assert leaders is None
            continue
        assert leaders.route.lanes == tuple(adapter.route.lanes)
        np.testing.assert_allclose(leaders.position, seen, atol=0.05)  # observed as float32
        assert leaders.corridor == adapter.scenario.path.corridor
