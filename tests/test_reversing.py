"""Road users that reverse (:attr:`IntervalModel.reversing
<risk_env.highway.lanes.interval.IntervalModel.reversing>`): highway-env's lane keeping steers the
wrong way in reverse, so their boxes and the rollout's bodies widen across by how far they may
reverse."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("highway_env")

from highway_helpers import LEFT_TURN, measurement  # noqa: E402

from risk_env.highway import LanePredictor  # noqa: E402
from risk_env.highway.lanes.beliefs import reverse_drift  # noqa: E402
from risk_env.highway.lanes.interval import IntervalModel  # noqa: E402
from risk_env.highway.lanes.predictor import EgoPlan  # noqa: E402
from risk_env.highway.lanes.rollout import REVERSING, roll_out  # noqa: E402

T = 0.5
STEPS = 8
EXIT_BESIDE = ("il0", "o0", 0)
"""The exit lane beside the ego's approach, driven the other way."""
SWITCHES = {"split_yield": True, "centred": True, "fitted": True}


def test_the_drift_grows_with_the_distance_reversed_up_to_its_cap():
    forward = np.array([3.0, 1.0, 0.0, 0.0, 2.0])
    assert np.array_equal(reverse_drift(forward, T, 1.0, 1.5), np.zeros(5))
    backward = np.full(6, -1.0)  # 0.5 m a step
    assert reverse_drift(backward, T, 1.0, 1.5) == pytest.approx([0.0, 0.5, 1.0, 1.5, 1.5, 1.5])
    assert reverse_drift(backward, T, 0.5, 10.0) == pytest.approx([0.0, 0.25, 0.5, 0.75, 1.0, 1.25])
    # a step that ends reversing counts at its lowest speed
    braking = np.array([1.0, -2.0, 0.0])
    assert reverse_drift(braking, T, 1.0, 9.0) == pytest.approx([0.0, 1.0, 2.0])


def boxes(network, rows, **switches):
    intervals = IntervalModel(**SWITCHES, **switches)
    predictor = LanePredictor(network, T, longitudinal="interval", intervals=intervals)
    return predictor.predict_scene(np.asarray(rows)[None], STEPS)[0]


def test_a_reversing_road_user_is_widened_across_and_one_driving_on_is_not(network):
    reversing = measurement(network, EXIT_BESIDE, 10.0, -2.0)
    plain, wide = boxes(network, reversing), boxes(network, reversing, reversing=True)
    cap = IntervalModel().drift_cap
    for a, b in zip(plain, wide, strict=True):
        grown = b.beliefs.half_y - a.beliefs.half_y
        assert grown[0] == pytest.approx(0.0)  # now: where it is measured
        assert np.all(np.diff(grown) >= -1e-9) and grown[1] >= 0.5 - 1e-9  # 1 m back by then at most
        assert grown[-1] == pytest.approx(cap)
        assert np.allclose(a.beliefs.half_x, b.beliefs.half_x) and np.allclose(a.beliefs.x, b.beliefs.x)
    driving = measurement(network, EXIT_BESIDE, 10.0, 8.0)  # leaving at the limit, nobody ahead
    for a, b in zip(boxes(network, driving), boxes(network, driving, reversing=True), strict=True):
        assert np.allclose(a.beliefs.half_y, b.beliefs.half_y)
    narrow = boxes(network, reversing, reversing=True, drift_rate=0.1, drift_cap=0.2)
    assert max(float(m.beliefs.half_y[-1] - p.beliefs.half_y[-1]) for m, p in zip(narrow, plain)) == (
        pytest.approx(0.2)
    )


def test_the_rollout_widens_a_reversing_road_user_beside_the_egos_path(network):
    """A car reversing on the exit beside the ego's approach, 8 m in, the ego 3 m before its line:
    4 m between the lanes' centres keep it clear of the ego going, unless it drifts more than 2 m
    (as it may when it reverses far enough, at the drift's default rate and cap, or at once, at a
    larger rate and cap)."""
    approach = network.get_lane(LEFT_TURN[0])
    ego = measurement(network, LEFT_TURN[0], approach.length - 3.0, 0.0)
    plan = EgoPlan(LEFT_TURN, 3.0, 8.0)

    def rolled(speed, **switches):
        car = measurement(network, EXIT_BESIDE, 8.0, speed)[None]
        intervals = IntervalModel(split_yield=True, centred=True, **switches)
        predictor = LanePredictor(network, T, longitudinal="interval", intervals=intervals, ego=lambda: ego)
        return roll_out(predictor, car, plan)

    assert rolled(-3.0).through and rolled(-3.0, reversing=True).through
    wide = rolled(-3.0, reversing=True, drift_rate=3.0, drift_cap=3.0)
    assert not wide.through and wide.reason.startswith("slow run: road user 0 (il0>o0) at 0.00 s")
    assert rolled(-6.0).through  # 3 m back: into the junction, where the ego turns
    fast = rolled(-6.0, reversing=True)
    assert not fast.through and "road user 0 (il0>o0)" in fast.reason


def test_the_rollout_moves_a_road_user_rolling_back_on_at_its_speed_and_heading(network):
    """A car in the ego's exit rolling back toward the junction: its lane's runs have it brake to a
    stop at once (nobody is behind it), but highway-env's car may go on rolling back (a leader too
    close keeps its IDM braking): with ``reversing`` it also moves on at its measured speed and
    heading; below :data:`REVERSING` it does not."""
    approach = network.get_lane(LEFT_TURN[0])
    ego = measurement(network, LEFT_TURN[0], approach.length - 3.0, 0.0)
    plan = EgoPlan(LEFT_TURN, 3.0, 8.0)

    def rolled(speed, **switches):
        car = measurement(network, LEFT_TURN[2], 15.0, speed)[None]
        intervals = IntervalModel(split_yield=True, centred=True, **switches)
        predictor = LanePredictor(network, T, longitudinal="interval", intervals=intervals, ego=lambda: ego)
        return roll_out(predictor, car, plan)

    assert rolled(-3.0).through
    back = rolled(-3.0, reversing=True)
    assert not back.through and "road user 0 (rolling back)" in back.reason
    assert rolled(-0.9 * REVERSING, reversing=True).through


@pytest.mark.parametrize(("name", "value"), [("drift_rate", -1.0), ("drift_cap", float("nan"))])
def test_bad_drift_numbers_are_named(name, value):
    with pytest.raises(ValueError, match=f"IntervalModel.{name}"):
        IntervalModel(**{name: value})
    with pytest.raises(TypeError, match="IntervalModel.reversing"):
        IntervalModel(reversing=1)


def test_the_prediction_benchmark_scores_the_samples_of_a_car_rolling_back_again():
    """Four steps of a car on the exit beside the ego's approach: it drives away, stops, rolls back;
    a sample is ``reversing`` when the car rolls back at the prediction or by the scored step, and
    the phase ``reversing`` scores those samples again (``all`` keeps every one)."""
    from benchmarks import prediction as bench
    from benchmarks import prediction_samples as samples
    from risk_env.prediction import ConstantPredictor
    from risk_env.scenario.scenario import Scenario

    speeds = [2.0, 0.0, -1.0, -2.0]
    steps = [
        {
            "ids": [1, 2],
            "ego": [True, False],
            "m": np.array([[2.0, 40.0, -np.pi / 2, 0.0, 0.0], [-2.0, 20.0 + 0.5 * t, np.pi / 2, v, 0.0]]),
            "lane": [("o0", "ir0", 0), EXIT_BESIDE],
            "crashed": np.array([False, False]),
            "signal": np.zeros((2, 2)),
            "route": [("o0", "ir0", "il1", "o1"), ("il0", "o0")],
        }
        for t, v in enumerate(speeds)
    ]
    scored = samples.score_episode(steps, {"constant": ConstantPredictor(Scenario.preset("low"))}, 0.05)
    s = scored["constant"]
    # predictions at t = 0, 1, 2 scored 1..3 steps on: (t, n) -> rolls back by t + n
    expected = [t + n >= 2 for t in range(3) for n in range(1, 4 - t)]
    assert s["reversing"].tolist() == expected
    rows = bench.summarise(scored, T)
    count = {r["phase"]: sum(q["samples"] for q in rows if q["phase"] == r["phase"]) for r in rows}
    assert count["reversing"] == sum(expected) and count["all"] == len(expected)
