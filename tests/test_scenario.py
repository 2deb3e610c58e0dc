import dataclasses
import math

import pytest

from risk_env.scenario import OVERRIDES, RISK_TOLERANCES, Scenario, Uncertainty


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
