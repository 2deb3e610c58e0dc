"""The warm-up: every NLP an agent can run is built before the episode (``prepare()``), so that no
step builds one; counted by the process-wide cache's counters, never by wall time."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("highway_env")

from agents import RMPC  # noqa: E402
from agents.mpc.nlp import solver  # noqa: E402
from agents.mpc.objects import Slots  # noqa: E402
from risk_env.scenario.scenario import Scenario  # noqa: E402

SHORT = {"horizon": 4}
"""A short horizon: cheap builds, the same packing and lanes."""


def test_the_capacities_are_what_the_packing_can_give():
    """Every row count :meth:`Slots.packing` returns for any number of active rows is among
    :meth:`Slots.capacities`, and nothing else is."""
    import numpy as np

    class Modes:
        max_modes = 3

    for objects in (1, 2, 5, 12):
        slots = Slots(Scenario(), objects, Modes())
        given = set()
        for active in range(slots.rows + 1):
            flags = np.zeros(slots.rows, bool)
            flags[:active] = True
            given.add(slots.packing(flags, data=False)[0])
        assert given == set(slots.capacities(data=False))
    assert Slots(Scenario(), 2).capacities(data=False) == (None,)  # the paper's: never packed
    assert Slots(Scenario(), 2, Modes()).capacities(data=True) == (None,)  # risk data: never packed


def test_after_the_warm_up_no_step_of_an_episode_builds():
    """The adapter prepares every lane's agent at its reset; the episode's steps then build
    nothing (the cache's build counter stays), a second preparation builds nothing either."""
    from risk_env.highway import IntersectionAdapter, make_intersection_env

    env = make_intersection_env(duration=3, initial_vehicle_count=6)
    adapter = IntersectionAdapter(
        env, lambda s, **kw: RMPC(s, max_solve_time=math.inf, **kw), slots=2, **SHORT
    )
    obs, _ = env.reset(seed=1)
    adapter.reset()
    assert adapter.route is not None and len(adapter._agents) == len(adapter.route.paths) == 3
    built = solver.CACHE_COUNTS.builds
    agent = adapter.agent
    kinds = {(v, r) for v, r in agent._problems}
    assert {r for _, r in kinds} == {1, 2, 4, 6}  # 2 objects x 3 modes, packed
    assert {v for v, _ in kinds} == {"free", "general", "general_soft"}
    assert all(a.prepare() == 0.0 for a in adapter._agents.values())
    steps, done, lanes, active = 0, False, set(), 0
    while not done:
        action, _ = adapter.predict(obs)
        obs, _, terminated, truncated, _ = env.step(action)
        steps, lanes = steps + 1, lanes | {adapter.lane}
        active += adapter.last_solve.variant != "free"
        done = terminated or truncated
    assert steps >= 4 and active >= 1  # the rows were in use
    assert solver.CACHE_COUNTS.builds == built


def test_without_the_warm_up_a_step_builds():
    """The counter sees a step's build: the test above cannot pass by a counter that never moves."""
    from risk_env.highway import IntersectionAdapter, make_intersection_env

    env = make_intersection_env(duration=1, initial_vehicle_count=6)
    adapter = IntersectionAdapter(
        env,
        lambda s, **kw: RMPC(s, max_solve_time=math.inf, **kw),
        slots=2,
        warm_up=False,
        horizon=3,  # an ego no other test builds: the problems are new to this process
        ego_radius=1.95,
    )
    obs, _ = env.reset(seed=1)
    adapter.reset()
    built = solver.CACHE_COUNTS.builds
    adapter.predict(obs)
    assert solver.CACHE_COUNTS.builds > built


def test_the_smpc_with_a_shared_budget_prepares_the_zero_tolerance_form_too():
    from agents import SMPC

    scenario = Scenario.preset("low", severity="probability").replace(horizon=3)
    agent = SMPC(scenario, risk_budget=0.05, risk_tolerance=math.inf, max_solve_time=math.inf)
    assert agent._step_forms() == {"general", "zero"}
    plain = SMPC(scenario, risk_tolerance=0.01, max_solve_time=math.inf)
    assert plain._step_forms() == {"general"}
