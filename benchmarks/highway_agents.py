r"""The agents of the intersection commands: what each name means there, its label, its driver.

Names follow :mod:`benchmarks.agent_names`; at the intersection they read:

- ``rmpc[:RISK]``: :class:`agents.RMPC`, robust against every predicted mode of weight at least
  ``--mode-threshold`` of every planned-for vehicle;
- ``smpc[:RISK]`` (no further part): :class:`agents.SMPC` with the command's ``--severity`` and an
  episode risk budget $B$ = ``--budget``, no per-step bound (``risk_tolerance=inf``: the budget
  alone); ``smpc[:RISK]:budget=B`` the same with budget $B$;
- ``smpc[:RISK]:SEVERITY:TOLERANCE``: the per-step bound $\epsilon$ alone (no budget), e.g.
  ``smpc:probability:0.01``; ``...:budget=B`` adds a budget to it;
- ``idm``: :class:`risk_env.highway.IDMEgo`, highway-env's own driver on the ego's route;
- ``hindsight``: :class:`benchmarks.highway_hindsight.HindsightEgo`, the first wait-then-go
  schedule that reaches the goal unharmed, found by simulating the episode's future (a reference
  that knows what no planner can, not a planner).

A budget is finite and $\ge 0$ and, in the probability severity, at most 1 (a chance per episode).
"""

from __future__ import annotations

import argparse
import functools
import math
from dataclasses import dataclass
from typing import Any

from benchmarks import cli
from benchmarks.agent_names import AgentName, number, parse_agent

KINDS = ("rmpc", "smpc", "idm", "hindsight")
"""The kinds of agent the intersection commands run."""
ADAPTER_CORRIDOR = 1.0
"""The adapter's corridor [m] (:data:`risk_env.highway.adapter.ADAPTER_DEFAULTS`) when the options
name none."""
ADAPTER_OBJECT_RADIUS = 2.0
"""The adapter's object disc radius [m] (:data:`risk_env.highway.adapter.ADAPTER_DEFAULTS`) when the
options name none."""
DEFAULT_BUDGET = 0.05
"""B of the plain ``smpc`` [the severity's unit per episode]: a 5 % chance of a collision per
episode in the probability severity."""


@dataclass(frozen=True)
class HighwayAgent:
    """An agent as the intersection commands run it: every part resolved."""

    kind: str
    """``rmpc``, ``smpc``, ``idm`` or ``hindsight``."""
    variant: str = ""
    """The risk estimator (``worst_case``, ``exact``, ...); empty for ``idm``."""
    severity: str = ""
    """The SMPC's severity (the command's ``--severity`` unless named)."""
    tolerance: float = math.inf
    r"""The SMPC's per-step bound $\epsilon$ [the severity's unit]; ``inf``: none."""
    budget: float | None = None
    """The SMPC's episode risk budget $B$ [the severity's unit]; None: none."""

    @property
    def name(self) -> str:
        """The full name, as the tables print it (``smpc:exact:budget=0.05``,
        ``smpc:exact:probability:0.01``); it reads back as this agent with the same ``--severity``."""
        step = math.isfinite(self.tolerance)
        return str(
            AgentName(
                self.kind,
                self.variant,
                self.severity if step else None,
                self.tolerance if step else None,
                self.budget,
            )
        )

    @property
    def label(self) -> str:
        """What the agent is, in words: ``"SMPC (exact risk), probability severity, episode budget
        0.05, no per-step bound"``."""
        if self.kind == "idm":
            return "highway-env IDM"
        if self.kind == "hindsight":
            return "hindsight: the first wait-then-go schedule that arrives unharmed (knows the future)"
        risk = self.variant.replace("_", " ")
        if self.kind == "rmpc":
            return f"RMPC ({risk} risk)"
        parts = [f"SMPC ({risk} risk)", f"{self.severity} severity"]
        if math.isfinite(self.tolerance):
            parts.append(f"epsilon {number(self.tolerance)} per step")
        if self.budget is not None:
            parts.append(f"episode budget {number(self.budget)}")
            if not math.isfinite(self.tolerance):
                parts.append("no per-step bound")
        return ", ".join(parts)


def check_budget(value: float, severity: str, what: str = "budget") -> float:
    r"""``value`` as an episode risk budget in ``severity``'s unit: finite, $\ge 0$ and, for the
    probability severity, at most 1; else ``ValueError`` naming ``what``."""
    value = float(value)
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f"{what} {value!r} must be finite and >= 0 [the severity's unit per episode]")
    if severity == "probability" and value > 1.0:
        raise ValueError(
            f"{what} {value:g} exceeds 1: with the probability severity a budget is the chance of a"
            " collision per episode"
        )
    return value


def resolve(agent: AgentName | str, severity: str, budget: float) -> HighwayAgent:
    """The agent ``agent`` names (see the module), an SMPC without a severity given ``severity``
    and, naming neither a tolerance nor a budget, the budget ``budget``. Raises ``ValueError``
    naming the agent for a bad name or budget."""
    a = parse_agent(agent, KINDS) if isinstance(agent, str) else agent
    if a.kind != "smpc":
        return HighwayAgent(a.kind, a.variant)
    sev = a.severity or severity
    tolerance = math.inf if a.tolerance is None else float(a.tolerance)
    spent = a.budget if a.budget is not None else (float(budget) if a.severity is None else None)
    if spent is not None:
        check_budget(spent, sev, f"agent {str(a)!r}: the budget")
    return HighwayAgent("smpc", a.variant, sev, tolerance, spent)


def built_problems() -> frozenset[Any]:
    """The keys of the MPCs' process-wide cache of built NLPs
    (:func:`agents.mpc.nlp.solver.cached_problem`)."""
    from agents.mpc.nlp import solver

    return frozenset(getattr(solver, "_SOLVER_CACHE", {}))


class Builder:
    """Builds the adapter's agents with ``factory`` and keeps the keys of the NLPs their
    construction built (:attr:`built`), so that a step's own builds can be told apart: an MPC
    builds each size of its problem when a step first needs it (with a predictor's modes as
    parameters), inside the step's solve time."""

    def __init__(self, factory: Any) -> None:
        self.factory = factory
        self.built: set[Any] = set()

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        before = built_problems()
        agent = self.factory(*args, **kwargs)
        self.built |= built_problems() - before
        return agent


def make_driver(agent: HighwayAgent, env: Any, args: Any, predictor: str) -> Any:
    """The driver of ``agent`` for ``env``: the IDM, the hindsight reference, or the MPC through
    :class:`risk_env.highway.IntersectionAdapter` with ``predictor`` and the options of ``args``
    (``uncertainty``, ``slots``, ``max_solve_time``, ``mode_threshold``, ``budget_share``,
    ``lane_pieces``, ``interval``, ``gate``)."""
    from agents import RMPC, SMPC
    from risk_env.highway import IDMEgo, IntersectionAdapter

    if agent.kind == "idm":
        return IDMEgo(env)
    if agent.kind == "hindsight":
        from benchmarks.highway_hindsight import HindsightEgo

        return HindsightEgo(env)
    options: dict[str, Any] = {"risk": agent.variant, "mode_threshold": args.mode_threshold}
    if args.max_solve_time is not None:
        options["max_solve_time"] = args.max_solve_time
    if getattr(args, "restart_standing", False):
        options["restart_standing"] = True
    if agent.kind == "smpc":
        options["risk_tolerance"] = agent.tolerance
        if agent.budget is not None:
            options |= {"risk_budget": agent.budget, "budget_share": args.budget_share}
    pieces = getattr(args, "lane_pieces", 1)
    switches = tuple(getattr(args, "interval", ()))
    if predictor in ("lane", "lane+interval") and (pieces > 1 or (switches and predictor == "lane+interval")):
        predictor = built_predictor(predictor, env, pieces, switches)
    return IntersectionAdapter(
        env,
        Builder(functools.partial(RMPC if agent.kind == "rmpc" else SMPC, **options)),
        uncertainty=args.uncertainty,
        severity=agent.severity or args.severity,
        slots=args.slots,
        predictor=predictor,
        corridor=getattr(args, "corridor", ADAPTER_CORRIDOR),
        gate=gate_settings(args),
        **body_overrides(args),
        **ego_overrides(args, env),
    )


def ego_overrides(args: argparse.Namespace, env: Any = None) -> dict[str, Any]:
    """The adapter's scenario overrides for the ego from ``--v-ref`` and ``--ego-accel`` (the lanes'
    $v_{max}$ rises to a higher $v_{ref}$) and, with ``--car-turning``, the curvature
    limit of ``env``'s car (:func:`risk_env.highway.common.bicycle_curvature`)."""
    from risk_env.highway.adapter import ADAPTER_DEFAULTS

    v_ref = getattr(args, "v_ref", ADAPTER_DEFAULTS["v_ref"])
    overrides = {"v_ref": v_ref, "v_max": max(ADAPTER_DEFAULTS["v_max"], v_ref)}
    accel = getattr(args, "ego_accel", None)  # None: the scenario's
    if accel is not None:
        overrides["accel_max"] = accel
    if getattr(args, "car_turning", False):
        from risk_env.highway.common import bicycle_curvature, unwrapped_highway

        overrides["curvature_max"] = bicycle_curvature(unwrapped_highway(env))
    return overrides


def body_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The adapter's scenario overrides for the vehicles' shapes in the MPCs' rows: ``--car-discs``
    n > 1: the ego and every object as n discs covering highway-env's car
    (:func:`risk_env.risk.bodies.cover_radius`); else the object's disc of ``--object-radius``."""
    radius = getattr(args, "object_radius", ADAPTER_OBJECT_RADIUS)
    discs = getattr(args, "car_discs", 1)
    if discs == 1:
        return {"object_radius": radius}
    if radius != ADAPTER_OBJECT_RADIUS:
        raise ValueError(
            f"--object-radius {radius:g} with --car-discs {discs}: the discs' radius covers the car, give one"
        )
    from highway_env.vehicle.kinematics import Vehicle

    from risk_env.risk.bodies import cover_radius

    r = cover_radius(Vehicle.LENGTH, Vehicle.WIDTH, discs)
    body = {"discs": discs, "length": Vehicle.LENGTH, "radius": r}
    return {f"{who}_{k}": v for who in ("ego", "object") for k, v in body.items()}


INTERVAL_SWITCHES = (
    "split_yield",
    "centred",
    "fitted",
    "yield_to_ego",
    "ego_ahead",
    "upper_yields",
    "reversing",
)
"""The interval prediction's switches a benchmark's ``--interval`` may turn on
(:class:`~risk_env.highway.lanes.interval.IntervalModel`'s bool fields of these names)."""


def interval_switches(text: str) -> tuple[str, ...]:
    """``type=`` of ``--interval``: a comma list of :data:`INTERVAL_SWITCHES` to turn on ("" for none)."""
    items = [item for item in cli._items(text) if item] if text.strip() else []
    bad = [item for item in items if item not in INTERVAL_SWITCHES]
    if bad:
        names = ", ".join(repr(b) for b in bad)
        raise argparse.ArgumentTypeError(
            f"unknown interval switch {names}; expected from {', '.join(INTERVAL_SWITCHES)}"
        )
    return tuple(dict.fromkeys(items))


def add_interval_option(parser: argparse.ArgumentParser) -> None:
    """``--interval``: switches of the ``lane+interval`` predictor's
    :class:`~risk_env.highway.lanes.interval.IntervalModel` to turn on."""
    parser.add_argument(
        "--interval",
        type=interval_switches,
        default=(),
        help="comma list of the lane+interval predictor's switches to turn on: split_yield (each mode"
        " held or free, weighted by the yielding rule), centred (each box centred on its interval),"
        " fitted (each box the tightest in its frame, about the stretch it holds: on a curve no longer"
        " as far outside the arc as inside it),"
        " yield_to_ego (no box runs through a standing ego from one that follows it or yields to it),"
        " ego_ahead (the fast runs brake for the ego on every lane highway-env's connected search"
        " covers), upper_yields (the fast runs obey the yielding rule, as the mean does),"
        " reversing (a road user that may reverse is widened across: highway-env's lane keeping"
        " steers the wrong way in reverse)",
    )


def built_predictor(name: str, env: Any, pieces: int = 1, switches: tuple[str, ...] = ()) -> Any:
    """The predictor ``name`` for ``env`` (:func:`risk_env.highway.predictors.highway_predictor`),
    with P = ``pieces`` and, for ``"lane+interval"``, the interval ``switches`` on."""
    from risk_env.highway.predictors import highway_predictor

    intervals = interval_model(switches) if name == "lane+interval" else None
    return highway_predictor(name, env, pieces=pieces, intervals=intervals)


def interval_model(switches: tuple[str, ...]) -> Any:
    """The :class:`~risk_env.highway.lanes.interval.IntervalModel` with ``switches`` (of
    :data:`INTERVAL_SWITCHES`) on, the rest at their defaults."""
    from risk_env.highway.lanes.interval import IntervalModel

    return IntervalModel(**dict.fromkeys(switches, True))


def add_gate_options(parser: argparse.ArgumentParser) -> None:
    """``--signals`` and the junction gate's settings (:class:`risk_env.highway.gate_judge.GateSettings`)."""
    from risk_env.highway.gate_judge import JUDGES, MODE_JUDGES, GateSettings

    defaults = GateSettings()
    parser.add_argument(
        "--signals",
        action="store_true",
        help="the env observes the other vehicles' turn signals (highway-env's observe_intentions); the"
        " gate and the MPCs' lane predictor read them",
    )
    parser.add_argument(
        "--gate-judge",
        choices=JUDGES,
        default=defaults.judge,
        help="the gate judges each mode's boxes, mean car, boxes then mean car (near), or the stretch of"
        " its route then mean car (stretch)",
    )
    parser.add_argument(
        "--gate-tolerance",
        type=cli.unit_interval,
        default=defaults.tolerance,
        help="the chance of a conflict the gate accepts (0: none)",
    )
    parser.add_argument(
        "--gate-clearance",
        type=cli.positive_float,
        default=defaults.clearance,
        help="the gate's clearance [m]",
    )
    parser.add_argument(
        "--gate-margin", type=cli.nonnegative_float, default=defaults.margin, help="the gate's margin [s]"
    )
    parser.add_argument(
        "--gate-given-ego",
        action="store_true",
        help="the gate predicts the others given that the ego goes (lane+interval)",
    )
    parser.add_argument(
        "--gate-slow-approach",
        action="store_true",
        help="while the gate is closed the MPCs' reference speed lets half the braking stop at the line",
    )
    parser.add_argument(
        "--gate-hard-stop",
        action="store_true",
        help="while the gate is closed the applied speed is clipped so too: nothing passes the line",
    )
    parser.add_argument(
        "--gate-follow",
        action="store_true",
        help="the agents follow road users ahead on the ego's route: their boxes span its corridor",
    )
    parser.add_argument(
        "--gate-keep-open",
        choices=MODE_JUDGES,
        default=defaults.keep_open,
        help="the judge by which an open gate closes again before the ego commits (default: the gate's own)",
    )
    parser.add_argument(
        "--gate-passage",
        action="store_true",
        help="the ego drives a passage the rollout verified, without the others' boxes (lane+interval)",
    )
    parser.add_argument(
        "--gate-leader-cap",
        action="store_true",
        help="the reference and applied speeds are capped so that the approach braking stops the ego"
        " behind the road user ahead on its route",
    )
    parser.add_argument(
        "--gate-approach-braking",
        type=cli.fraction,
        default=defaults.approach_braking,
        help="the share of the ego's braking the slow approach and the hard stop plan with (0.5: half)",
    )


def gate_settings(args: Any) -> Any:
    """``IntersectionAdapter``'s ``gate`` from the options: False (``--no-gate``), or the settings."""
    from risk_env.highway.gate_judge import GateSettings

    if not getattr(args, "gate", True):
        return False
    defaults = GateSettings()
    return GateSettings(
        clearance=getattr(args, "gate_clearance", defaults.clearance),
        margin=getattr(args, "gate_margin", defaults.margin),
        judge=getattr(args, "gate_judge", defaults.judge),
        tolerance=getattr(args, "gate_tolerance", defaults.tolerance),
        given_ego=getattr(args, "gate_given_ego", defaults.given_ego),
        slow_approach=getattr(args, "gate_slow_approach", defaults.slow_approach),
        hard_stop=getattr(args, "gate_hard_stop", defaults.hard_stop),
        follow=getattr(args, "gate_follow", defaults.follow),
        approach_braking=getattr(args, "gate_approach_braking", defaults.approach_braking),
        keep_open=getattr(args, "gate_keep_open", defaults.keep_open),
        passage=getattr(args, "gate_passage", defaults.passage),
        leader_cap=getattr(args, "gate_leader_cap", defaults.leader_cap),
    )
