import dataclasses
import math
import re

import numpy as np
import pytest

from risk_env.models.path import point, project
from risk_env.scenario.scenario import (
    OVERRIDES,
    RISK_TOLERANCES,
    SCENE_NAMES,
    CrossingObject,
    Pose,
    Scenario,
    Uncertainty,
)


def test_paper_numbers():
    s = Scenario.preset("low")
    assert (s.dt, s.horizon, s.mc_samples, s.grid_points) == (0.5, 6, 500, 40)
    assert s.ego.start.as_tuple() == (-10.0, 10.0, 0.0)
    assert s.object.start.as_tuple() == (5.0, -5.0, math.pi / 2)
    assert (s.object.speed, s.object.turn_rate) == (3.0, 1e-4)
    assert s.collision_distance == 3.0
    assert s.path.curvature == 0.003 and s.path.lambda_start == -95.0
    assert s.uncertainty.velocity_bounds0 == (-5.0, 5.0)
    assert RISK_TOLERANCES == (0.0, 500.0, 1000.0, 1500.0, 2000.0, 2500.0)


@pytest.mark.parametrize(
    ("name", "q", "delta"), [("low", 0.1, 1.0), ("medium", 0.8, 2.0), ("high", 1.5, 3.0)]
)
def test_presets_follow_table_one(name, q, delta):
    u = Scenario.preset(name).uncertainty
    assert u.sigma_growth == (q, q, q)
    assert u.box_growth == (delta, delta, delta)
    assert u.sigma0 == (0.0, 0.0, 0.0)


def test_overrides_reach_nested_fields():
    s = Scenario.preset(
        "high", ego_start=(1, 2, 0.1), object_speed=2.0, v_ref=3.0, severity="plastic", v_min=-2.0, horizon=8
    )
    assert s.ego.start.as_tuple() == (1.0, 2.0, 0.1)
    assert s.object.speed == 2.0 and s.ego.v_ref == 3.0 and s.ego.v_min == -2.0
    assert s.severity == "plastic" and s.horizon == 8
    assert s.uncertainty.sigma_growth == (1.5, 1.5, 1.5)


def test_every_override_name_maps_to_a_field():
    s = Scenario()
    for name, (part, attr) in OVERRIDES.items():
        owner = s if part is None else getattr(s, part)
        assert attr in {f.name for f in dataclasses.fields(owner)}, name


def test_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        Scenario().dt = 1.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"ego_radius": -1.0}, "ego.radius"),
        ({"horizon": 0}, "horizon"),
        ({"horizon": 2.5}, "horizon"),
        ({"dt": float("nan")}, "dt"),
        ({"risk_tolerance": -1.0}, "risk_tolerance"),
        ({"severity": "energy"}, "severity"),
        ({"v_min": 5.0, "v_max": 4.0}, "v_min"),
        ({"v_ref": 20.0}, "v_ref"),
        ({"sigma_growth": (0.1, -0.1, 0.1)}, "sigma_growth"),
        ({"sigma_growth": (0.1, 0.1)}, "sigma_growth"),
        ({"object_start": (1.0, 2.0)}, "object.start"),
        ({"curvature": 0.5}, "curvature"),
        ({"grid_points": 1}, "grid_points"),
        ({"mc_samples": 0}, "mc_samples"),
        ({"object_speed": 9.0}, "object.speed"),
    ],
)
def test_bad_values_name_the_field(overrides, message):
    with pytest.raises((ValueError, TypeError), match=message):
        Scenario.preset("low", **overrides)


def test_unknown_names_raise_with_suggestion():
    with pytest.raises(TypeError, match="did you mean object_speed"):
        Scenario.preset("low", object_sped=2.0)
    with pytest.raises(ValueError, match="unknown uncertainty preset 'extreme'"):
        Scenario.preset("extreme")
    with pytest.raises(ValueError, match="unknown uncertainty preset"):
        Uncertainty.preset("Low")


# ---------------------------------------------------------------- types, field by field
_SEQUENCES = {"ego_start": 3, "object_start": 3, "goal": 3, "initial_input": 2, "cost_weights": 4}
_SEQUENCES.update({name: 3 for name in ("sigma_growth", "box_growth", "sigma0")})
_SEQUENCES.update({"box_half_width0": 2, "velocity_bounds0": 2})
_INTEGERS = ("horizon", "max_steps", "mc_samples", "grid_points")
_TEXTS = ("severity",)


def _field_name(name: str) -> str:
    """How errors name an override: ``ego.mass`` for ``ego_mass``, ``dt`` for ``dt``."""
    part, attr = OVERRIDES[name]
    return attr if part is None else f"{part}.{attr}"


_FIELD_NAMES = {name: _field_name(name) for name in OVERRIDES}


def _wrong_values(name: str) -> list:
    common = ["1", None, 1j, object()]
    if name in _SEQUENCES:
        n = _SEQUENCES[name]
        return [*common, 1.0, "abc", ["1"] * n, [True] * n, [None] * n, [1j] * n]
    if name in _TEXTS:
        return [None, 1j, object(), ["paper"], 1]
    return [*common, True, np.True_, [1.0], np.array([1.0])]


@pytest.mark.parametrize(
    ("name", "value"), [(name, value) for name in OVERRIDES for value in _wrong_values(name)]
)
def test_every_field_rejects_wrong_types_by_its_own_name(name, value):
    with pytest.raises(TypeError) as error:
        Scenario.preset("low", **{name: value})
    message = str(error.value)
    assert re.match(rf"{re.escape(_FIELD_NAMES[name])}(\[\d\])? ", message), message
    assert "got " in message


def test_integer_fields_take_integral_types_only():
    for name in _INTEGERS:
        s = Scenario.preset("low", **{name: np.int16(12)})
        assert getattr(s, name) == 12 and type(getattr(s, name)) is int
        for bad in (12.0, np.float64(12.0), True, "12"):
            with pytest.raises(TypeError, match=f"{name} must be an integer"):
                Scenario.preset("low", **{name: bad})


def test_numbers_are_stored_as_python_floats():
    s = Scenario.preset(
        "low", ego_start=np.array([-10, 10, 0], dtype=np.int32), risk_tolerance=np.float32(0.5), dt=1
    )
    assert s.ego.start == Pose(-10.0, 10.0, 0.0)
    assert type(s.ego.start.x) is float and type(s.risk_tolerance) is float and type(s.dt) is float
    assert s.risk_tolerance == float(np.float32(0.5))
    assert s == Scenario.preset("low", ego_start=(-10.0, 10.0, 0.0), risk_tolerance=0.5, dt=1.0)


def test_nested_parts_must_have_their_types():
    with pytest.raises(TypeError, match=r"scenario\.ego must be a Ego, got 'x' \(str\)"):
        Scenario(ego="x")
    with pytest.raises(TypeError, match=r"Pose\.theta must be a real number .*'0' \(str\)"):
        Pose(0.0, 0.0, "0")


def test_observation_reach_of_the_paper_scenario():
    # ego: 80 steps of 0.5 s at |v| <= 8 m/s from (-10, 10); the object from (5, -5) at up to
    # 5 + 1 m/s plus a 1 m box per step (low uncertainty)
    reach = Scenario.preset("low").observation_reach()
    assert reach["ego position"][0] == pytest.approx(10.0 + 320.0, rel=1e-5)
    assert reach["object position"][0] == pytest.approx(5.0 + 80 * (6.0 * 0.5 + 1.0))
    assert reach["object speed"][0] == 6.0
    assert reach["ego turn rate"][0] == pytest.approx(0.8, rel=1e-5)
    assert all(value <= bound for value, bound, _, _ in reach.values())


# ---------------------------------------------------------------- several objects
def test_the_default_is_the_papers_single_object():
    s = Scenario.preset("low")
    assert len(s.objects) == 1 and s.object is s.objects[0]
    assert s.object == CrossingObject() and s.object.uncertainty is None
    assert s.collision_distances == (s.collision_distance,) == (3.0,)
    assert s.uncertainties == (s.uncertainty,)
    assert s.for_object(0) is s
    assert Scenario.preset("low", scene="paper") == s


def test_objects_from_dicts_with_their_own_numbers():
    s = Scenario.preset(
        "low",
        objects=[
            {"start": (1.0, 2.0, 0.5), "speed": 2.0, "turn_rate": 0.1},
            CrossingObject(start=Pose(3.0, 4.0, 0.0), radius=2.0),
            {"start": (5.0, 6.0, 1.0), "speed": 1.0, "mass": 80.0, "radius": 0.5, "uncertainty": "high"},
            {"speed": 1.0, "sigma_growth": (0.3, 0.3, 0.3), "box_growth": [2, 2, 2]},
        ],
    )
    assert len(s.objects) == 4 and all(isinstance(o, CrossingObject) for o in s.objects)
    assert s.object.start == Pose(1.0, 2.0, 0.5) and s.object.turn_rate == 0.1
    assert s.objects[1].radius == 2.0 and s.collision_distances == (3.0, 3.5, 2.0, 3.0)
    assert s.objects[2].mass == 80.0 and s.objects[2].uncertainty == Uncertainty.preset("high")
    # uncertainty keys start from the scenario's: only the named fields change
    own = s.objects[3].uncertainty
    assert own.sigma_growth == (0.3, 0.3, 0.3) and own.box_growth == (2.0, 2.0, 2.0)
    assert own.velocity_bounds0 == s.uncertainty.velocity_bounds0
    assert s.uncertainties == (s.uncertainty, s.uncertainty, Uncertainty.preset("high"), own)
    # the view of one object: its numbers, its uncertainty as the scenario's
    view = s.for_object(2)
    assert view.objects == (dataclasses.replace(s.objects[2], uncertainty=None),)
    assert view.uncertainty == Uncertainty.preset("high") and view.collision_distance == 2.0
    assert (view.ego, view.path, view.dt) == (s.ego, s.path, s.dt)


def test_flat_object_overrides_change_the_first_object():
    s = Scenario.preset("low", scene="two_crossing", object_speed=2.0, object_mass=500.0)
    assert (s.object.speed, s.object.mass) == (2.0, 500.0)
    assert s.objects[1] == Scenario.preset("low", scene="two_crossing").objects[1]
    t = Scenario.preset("low", objects=[{"speed": 1.0}, {"speed": -1.0}], object_start=(0.0, 0.0, 0.0))
    assert t.object.start == Pose(0.0, 0.0, 0.0) and t.object.speed == 1.0 and t.objects[1].speed == -1.0
    assert s.replace(object_speed=1.0).objects[1] == s.objects[1]


def test_scenes():
    two = Scenario.preset("medium", scene="two_crossing")
    assert len(two.objects) == 2 and two.objects[0] == Scenario.preset("medium").object
    second = two.objects[1]
    # the second crosses from the other side of the path: north of it, heading south
    lam = float(project(two.path, second.start.x, second.start.y))
    px, py, _ = point(two.path, lam)
    assert second.start.y > py + 10.0 and math.sin(second.start.theta) < -0.99
    assert len(Scenario.preset(scene="four_crossing").objects) == 4
    assert set(SCENE_NAMES) == {"paper", "two_crossing", "four_crossing"}
    with pytest.raises(ValueError, match=r"unknown scene 'two_crosing' \(did you mean 'two_crossing'\?\)"):
        Scenario.preset("low", scene="two_crosing")


@pytest.mark.parametrize(
    ("objects", "error", "message"),
    [
        ([{}, {"speed": None}], TypeError, r"objects\[1\]\.speed must be a real number .*got None"),
        ([{}, {"speed": float("nan")}], ValueError, r"objects\[1\]\.speed must be finite, got nan"),
        ([{"radius": -1.0}], ValueError, r"objects\[0\]\.radius must be > 0, got -1\.0"),
        ([{}, {}, {"mass": -5}], ValueError, r"objects\[2\]\.mass must be > 0, got -5"),
        ([{}, {"start": (1.0, float("inf"), 0.0)}], ValueError, r"objects\[1\]\.start\[1\] must be finite"),
        ([{}, {"start": (1.0, 2.0)}], ValueError, r"objects\[1\]\.start must have 3 entries"),
        ([{}, {"sped": 2.0}], TypeError, r"unknown key 'sped' in objects\[1\]; did you mean speed\?"),
        ([{"uncertainty": "extreme"}], ValueError, r"unknown objects\[0\]\.uncertainty 'extreme'"),
        ([{"uncertainty": 3}], TypeError, r"objects\[0\]\.uncertainty must be an Uncertainty"),
        ([{"sigma_growth": (0.1, -1.0, 0.1)}], ValueError, r"objects\[0\]\.uncertainty\.sigma_growth\[1\]"),
        ([{}, {"speed": 7.0}], ValueError, r"objects\[1\]\.speed 7\.0 m/s lies outside .* uncertainty\."),
        (
            [{}, {"speed": 2.0, "velocity_bounds0": (3.0, 4.0)}],
            ValueError,
            r"objects\[1\]\.speed 2\.0 m/s .* objects\[1\]\.uncertainty\.velocity_bounds0",
        ),
        (
            [{}, {"start": (2e5, 0.0, 0.0)}],
            ValueError,
            r"objects\[1\] position can reach .* objects\[1\]\.start",
        ),
        (
            [{}, {"turn_rate": 2e3}],
            ValueError,
            r"objects\[1\] turn rate can reach 2000 .* objects\[1\]\.turn_rate",
        ),
        ([], ValueError, "objects must hold at least one object"),
        ({"speed": 1.0}, TypeError, "objects must be a sequence of CrossingObject or dicts"),
        ([{}, 3.0], TypeError, r"objects\[1\] must be a CrossingObject or a dict of its fields, got 3\.0"),
    ],
)
def test_bad_objects_name_the_object_and_the_field(objects, error, message):
    with pytest.raises(error, match=message):
        Scenario.preset("low", objects=objects)


def test_observation_reach_covers_every_object():
    s = Scenario.preset(
        "low", scene="two_crossing", objects=[{}, {"start": (25.0, 32.0, -1.5), "uncertainty": "high"}]
    )
    reach = s.observation_reach()
    assert reach["objects[1] position"][0] == pytest.approx(
        32.0 + 80 * (8.0 * 0.5 + 3.0)
    )  # high: 5 + 3 m/s, 3 m
    assert reach["objects[0] speed"][0] == 6.0 and reach["objects[1] speed"][0] == 8.0
    assert "objects[1].uncertainty.box_growth" in reach["objects[1] position"][3]
