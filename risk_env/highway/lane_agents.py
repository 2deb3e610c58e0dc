r"""The adapter's agents (:class:`risk_env.highway.IntersectionAdapter`): one per lane of the route,
each built on the scenario re-posed on its lane, and **prepared before the episode**.

An MPC's NLP is built into its path (the lane's arc) and its row count (the packed object and mode
rows, :meth:`agents.mpc.objects.Slots.capacities`). Built inside a step, it costs that step up to
seconds of CPU, which under the wall-time cap cuts the step short and lets the fallback act. So when
the adapter knows the route (at its reset, or the first step of an episode) it builds the agent of
every lane of the route and calls its ``prepare()`` (:meth:`agents.PathFollowingMPC.prepare`):
every problem a step can run is built then, and no step of the episode builds one. Agents are kept
per lane geometry, so later episodes on the same lanes build nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from risk_env.highway.route import RoutePath
from risk_env.scenario.scenario import ReferencePath, Scenario

CURVE_SPEED_SHARE = 0.9
r"""On a circular lane $v_{ref}$ is capped to this share of $\omega_{max} r$ ($r$ the lane's radius),
so the lane stays followable (:class:`~risk_env.Scenario` requires $\kappa v_{ref} \le \omega_{max}$)."""


def lane_scenario(base: Scenario, path: ReferencePath) -> Scenario:
    """``base`` re-posed on the lane ``path`` (same numbers; its goal, curvature and start, and
    on a curve $v_{ref}$ within :data:`CURVE_SPEED_SHARE` of what the turn rate allows)."""
    v_ref = base.ego.v_ref
    if path.curvature != 0.0:
        v_ref = min(v_ref, CURVE_SPEED_SHARE * base.ego.omega_max / abs(path.curvature))
    return base.replace(goal=path.goal, curvature=path.curvature, lambda_start=path.lambda_start, v_ref=v_ref)


def lane_agent(
    agents: dict[ReferencePath, Any],
    path: ReferencePath,
    base: Scenario,
    make_agent: Callable[..., Any],
    slots: int,
    predictor: Any,
) -> Any:
    """The agent of lane ``path`` in ``agents``, built by ``make_agent(scenario, object_slots=slots,
    predictor=predictor)`` (no ``predictor`` when None) on its first call."""
    if path not in agents:
        extra = {} if predictor is None else {"predictor": predictor}
        agents[path] = make_agent(lane_scenario(base, path), object_slots=slots, **extra)
    return agents[path]


def prepare_route(
    agents: dict[ReferencePath, Any],
    route: RoutePath,
    base: Scenario,
    make_agent: Callable[..., Any],
    slots: int,
    predictor: Any,
) -> float:
    """Build the agent of every lane of ``route`` (:func:`lane_agent`) and call its ``prepare()``
    where it has one; the seconds the agents spent building their problems (0: none was new)."""
    built = 0.0
    for path in route.paths:
        agent = lane_agent(agents, path, base, make_agent, slots, predictor)
        if hasattr(agent, "prepare"):
            built += float(agent.prepare())
    return built
