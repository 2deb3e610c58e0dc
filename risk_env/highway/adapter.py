r"""Our MPC agents drive highway-env's controlled vehicle on ``intersection-v2`` (or ``-v1``).

:class:`IntersectionAdapter` sits between highway-env and an agent that speaks RiskCrossing
(``action, _ = agent.predict(obs)``, :mod:`risk_env.observation`): it turns highway-env's
``Kinematics`` observation into ours and our ``(v, omega)`` into highway-env's continuous
``(acceleration, steering)``, and offers the same ``predict`` itself, so anything that drives a
highway-env env with an SB3-style policy drives it.

**The reference path.** The MPC core follows one constant-curvature arc, a
:class:`~risk_env.scenario.scenario.ReferencePath` (:mod:`agents.mpc.nlp.ocp` builds its problem from it). The
controlled vehicle's route is a chain of highway-env lanes, each straight (curvature 0) or circular
(curvature 1/radius), so each lane *is* such an arc, exactly (:class:`RoutePath`). The adapter keeps
one agent per lane of the route, built on the scenario re-posed on that lane (same numbers,
``goal``/``curvature``/``lambda_start`` of the lane), and hands over to the next lane's agent when
the vehicle's closest point passes the end of its lane (``switch_ahead`` metres earlier if asked).
The approximation: within a horizon that runs past the end of a lane, the MPC's reference continues
that lane's arc (straight on, or round the circle) rather than turning into the next lane; the
plan bends at the hand-over, one step late. The new agent starts cold (no warm start).

**The objects.** The agent has ``slots`` object slots (default :data:`DEFAULT_SLOTS`; the adapter
builds its agents with ``object_slots=slots``) and one solve plans against every vehicle it is
handed (:mod:`agents.mpc.objects`). The adapter hands it every observed vehicle, nearest first, up to
the slot count; the other slots are flagged absent (no stand-in object, no choice of a "first
conflict"). Only when more vehicles are observed than there are slots are the farthest left out.
Each measurement is observed position, heading and speed; its turn rate is the change of its
heading since the previous step, when the
vehicle can be associated with one seen then (within :data:`TRACK_GATE` of where it was predicted),
else 0. highway-env's observation has no steering, so the heading stands in for the direction of
travel (they differ by the slip angle, up to ~0.2 rad in a tight turn).

**The ego** is measured with its direction of travel (heading plus the slip angle of the steering the
adapter applied) and speed; its last input is that speed with the turn rate last asked for. The
action: acceleration $(v - v_{now}) / T$ so that the speed reaches $v$ at the end of the step (the
unicycle jumps to $v$ at once, so highway-env's vehicle lags $(v - v_{now})\, T / 2$ metres behind
the plan per step), and the steering whose kinematic-bicycle turn rate at the step's mean speed is
$\omega$. It needs highway-env's kinematic vehicle (``"dynamical": False``) and an unnormalised,
absolute ``Kinematics`` observation with x, y, vx, vy and heading: :data:`INTERSECTION_CONFIG`
(:func:`make_intersection_env`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from risk_env import checks
from risk_env import observation as layout
from risk_env.highway.common import (
    INTERSECTION_CONFIG,
    VERSIONS,
    check_adapter_config,
    highway_scenario,
    make_intersection_env,
    policy_period,
    slip_angle,
    turn_signals,
    unwrapped_highway,
)
from risk_env.highway.control import highway_action
from risk_env.highway.gate import JunctionGate, check_gate, make_gate
from risk_env.highway.idm import IDMEgo, reached
from risk_env.highway.lane_agents import lane_agent, lane_scenario, prepare_route
from risk_env.highway.lanes.follow import Leaders, leader_gap, leader_speed
from risk_env.highway.lanes.routes import Route
from risk_env.highway.predictors import HIGHWAY_PREDICTORS, highway_predictor
from risk_env.highway.route import LaneIndex, RoutePath, lane_path
from risk_env.highway.tracking import TRACK_GATE, measure
from risk_env.models.path import path_error_vector, project
from risk_env.prediction.predictors import Predictor
from risk_env.scenario.scenario import ReferencePath, Scenario

ADAPTER_DEFAULTS: dict[str, Any] = {
    "v_ref": 8.0,
    "v_min": 0.0,
    "v_max": 10.0,
    "ego_radius": 2.0,
    "object_radius": 2.0,
    "corridor": 1.0,
}
"""Scenario values the adapter changes from the paper's for the intersection: $v_{ref}$ 8 m/s (the
lanes' limit and the ego's entry speed are 10), no reversing on a road, $v_{max}$ 10 m/s, discs of
2 m (highway-env's 5 x 2 m cars touch at centre distances of 2 to 5.4 m; two 2 m discs at 4 m),
a corridor of 1 m about the lane's centreline for the planned centre (the 2 m wide car stays in
its 4 m lane: the MPC may not leave the road to escape a prediction)."""

DEFAULT_SLOTS = 5
"""The agents' object slots: every observed vehicle up to this many is planned against."""


class IntersectionAdapter:
    """Lets an agent of ours drive highway-env's controlled vehicle (see the module docstring).

    ``action, _ = adapter.predict(highway_obs)`` returns highway-env's normalised
    ``(acceleration, steering)`` in [-1, 1]^2. A new episode is detected from ``episode_start``
    or from a new controlled vehicle; its route is read then from the env's road network (the map:
    the agents themselves read only observations).

    Args:
        env: a highway-env env configured as :data:`INTERSECTION_CONFIG` (or compatibly).
        make_agent: builds an agent for a scenario, e.g. ``agents.RMPC`` or
            ``functools.partial(agents.SMPC, risk="exact")``; called once per lane geometry as
            ``make_agent(scenario, object_slots=slots)``.
        uncertainty, risk_tolerance, **overrides: the scenario,
            :func:`risk_env.highway.highway_scenario` with :data:`ADAPTER_DEFAULTS` first.
        destination: the node the route leads to (default: the env's ``config["destination"]``).
        switch_ahead: hand over to the next lane this many metres [m] before the end of a lane
            (2 m: about half a step at $v_{ref}$, so the hand-over comes the step before the lane ends).
        slots: the agent's object slots $K$ (default :data:`DEFAULT_SLOTS`): the nearest $K$ observed
            vehicles are planned against, in one solve.
        predictor: how the agents predict the other vehicles: ``"lane"`` (default: their routes
            along highway-env's lanes, :class:`risk_env.highway.lanes.LanePredictor`), ``"constant"``
            (the paper's: constant speed and turn rate) or any :class:`risk_env.prediction.Predictor`;
            handed to ``make_agent`` as ``predictor=`` (not for ``"constant"``).
        warm_up: when the route is known, build every lane's agent and every NLP it can run
            (``prepare()``; :mod:`risk_env.highway.lane_agents`); False: each when first needed.
        gate: the junction gate (:mod:`risk_env.highway.gate`, default on): before the junction, the
            MPC gets a virtual stationary object at the stop line whenever the ego could not cross
            the junction before another vehicle's predicted bounds reach its path; False: none; a
            :class:`~risk_env.highway.gate_judge.GateSettings`: on, judging so (with
            ``slow_approach``, each step it sets the lane agent's ``speed_limit``, if it has one;
            with ``hard_stop``, it clips the applied speed so).
    """

    def __init__(
        self,
        env: gym.Env,
        make_agent: Callable[[Scenario], Any],
        uncertainty: str = "low",
        risk_tolerance: float = 0.0,
        destination: str | None = None,
        switch_ahead: float = 2.0,
        slots: int = DEFAULT_SLOTS,
        predictor: str | Predictor | None = "lane",
        warm_up: bool = True,
        gate: bool | Any = True,
        **overrides: Any,
    ) -> None:
        if not callable(make_agent):
            raise TypeError(
                "make_agent must be callable, Scenario -> agent (e.g. RMPC or"
                f" functools.partial(SMPC, risk='exact')), got {checks.describe(make_agent)}"
            )
        self.env = env
        base = unwrapped_highway(env)
        check_adapter_config(base)
        self.dt = policy_period(env)
        self.base_scenario = highway_scenario(
            env, uncertainty, risk_tolerance, **{**ADAPTER_DEFAULTS, **overrides}
        )
        """The scenario before re-posing on a lane (its path is the paper's, unused)."""
        self.destination = destination or base.config.get("destination")
        if not self.destination:
            raise ValueError("no destination: pass destination= or set the env's config['destination']")
        switch_ahead = checks.real("switch_ahead", switch_ahead)
        if not (math.isfinite(switch_ahead) and switch_ahead >= 0):
            raise ValueError(f"switch_ahead must be >= 0 [m], got {switch_ahead!r}")
        self.switch_ahead = float(switch_ahead)
        self.make_agent = make_agent
        if predictor is not None and not isinstance(predictor, Predictor):
            checks.text("predictor", predictor, HIGHWAY_PREDICTORS)
        self._predictor_arg = predictor
        self.predictor: Predictor | None = None
        """The other vehicles' predictor handed to the agents (None: the paper's, in the NLP); a
        named one is built on the road network at the first episode (the map: the same at every
        reset)."""
        self._agents: dict[ReferencePath, Any] = {}
        self.gate: JunctionGate | None = None  # the junction gate (None: off), at the first episode
        self._gate_on = check_gate(gate)  # its settings, or None: off
        if self._gate_on is not None and self._gate_on.follow and predictor in (None, "constant"):
            raise ValueError("GateSettings.follow needs a predictor of the lanes, got the paper's (constant)")
        self._agent_predictor: Predictor | None = None
        self._leader_route: Route | None = None  # with the gate's follow: the route as lanes
        self._ready = False
        self.warm_up = bool(warm_up)
        self.build_time = 0.0
        """Seconds the agents spent building their problems when routes were prepared."""
        self.route: RoutePath | None = None
        self.lane = 0
        """Index in :attr:`route` of the lane being followed."""
        self.slots = checks.integer("slots", slots, minimum=1)
        self.last_objects = np.zeros((0, 5))
        r"""Measurements ``(m, 5)``, $m \le$ :attr:`slots`, of the vehicles planned against at the last
        step, nearest first."""
        self.last_solves: list[Any] = []
        """The solve report of the last step (one)."""
        self._last_solve: Any = None
        self.last_observation: np.ndarray | None = None
        """The observation ``(10 + 6 K,)`` the agent got at the last step."""
        self._vehicle: Any = None
        self._tracks = np.zeros((0, 5))
        self._steering = 0.0
        self._omega = 0.0
        self._fresh = True

    # ---------------------------------------------------------------- public API
    @property
    def scenario(self) -> Scenario:
        """The scenario of the lane being followed."""
        return self._scenario_for(self.lane)

    @property
    def agent(self) -> Any:
        """The agent of the lane being followed."""
        return self._agent_for(self.lane)

    @property
    def last_solve(self) -> Any:
        """The solve report (``agents.SolveReport``) of the plan applied at the last step, or None."""
        return self._last_solve

    @property
    def last_solve_time(self) -> float:
        """Wall time [s] of the agent's solve of the last step."""
        return float(sum(getattr(r, "solve_time", 0.0) for r in self.last_solves if r is not None))

    @property
    def failures(self) -> int:
        """Failed solves this episode, over every lane's agent."""
        return sum(getattr(a, "failures", 0) for a in self._agents.values())

    def spent_risk(self) -> float:
        """The episode's risk spent so far by its agents' own estimators: the sum of every lane
        agent's ``spent_risk()`` (an SMPC with a budget; 0 for the others). Each lane's agent
        counts from its hand-over (its episode starts there), so an episode budget B holds per lane."""
        return float(sum(a.spent_risk() for a in self._agents.values() if hasattr(a, "spent_risk")))

    def reset(self) -> None:
        """Forget the episode. With the env reset (a controlled vehicle), read its route and prepare
        the agent of every lane (:mod:`risk_env.highway.lane_agents`); else the next ``predict``
        does."""
        self._vehicle = None
        base = unwrapped_highway(self.env)
        if getattr(base, "vehicle", None) is not None and getattr(base, "road", None) is not None:
            self._begin_episode(base)

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, None]:
        """highway-env observation ``(V, F)`` -> its action ``(2,)`` float32 (see the class)."""
        base = unwrapped_highway(self.env)
        if self._vehicle is not base.vehicle or (episode_start is not None and np.any(episode_start)):
            self._begin_episode(base)
        rows = self._rows(observation)
        x, y, heading, speed = rows[0]  # the ego's row
        theta = heading + slip_angle(self._steering)
        switched = self._advance(x, y)
        scenario = self._scenario_for(self.lane)
        others = self._measure_others(rows[1:])
        nearest = np.argsort(np.hypot(others[:, 0] - x, others[:, 1] - y), kind="stable")
        progress = self.route.progress(self.lane, x, y)
        signals = turn_signals(base, observation)  # None unless the env observes them
        virtual = np.zeros((0, 5)) if self.gate is None else self.gate.step(progress, speed, others, signals)
        if self._leader_route is not None and self._gate_on.follow:  # road users ahead are followed
            corridor = scenario.path.corridor
            self._agent_predictor.leaders = Leaders(self._leader_route, (x, y), corridor)
        verified = self.gate is not None and self.gate.verified_speed is not None
        self.last_objects = others[nearest[: 0 if verified else self.slots - len(virtual)]]
        pose = np.array([x, y, theta])
        error, lam = path_error_vector(scenario.path, pose, speed, scenario.ego.v_ref)
        planned = np.vstack([virtual, self.last_objects])
        obs = layout.build((x, y, theta), (speed, self._omega), lam, error, planned, self.slots)
        agent = self._agent_for(self.lane)
        cap = self._leader_speed(others, x, y)
        if self.gate is not None and hasattr(agent, "speed_limit"):
            agent.speed_limit = min(self.gate.stop_speed(), cap)
        action, _ = agent.predict(obs, episode_start=self._fresh or switched, deterministic=True)
        self._fresh = False
        self.last_observation = obs
        self._last_solve = getattr(agent, "last_solve", None)
        if self.gate is not None:  # the virtual object's risk is not charged to a budget
            self.gate.refund(agent, self._last_solve)
        self.last_solves = [self._last_solve]
        v, omega = (float(a) for a in action)
        if self.gate is not None:
            v = min(self.gate.allowed_speed(v), cap)
        highway_action, self._steering = self.highway_action(v, omega, speed, self._steering)
        self._omega = omega
        return highway_action, None

    def _leader_speed(self, others: np.ndarray, x: float, y: float) -> float:
        """With the gate's ``leader_cap``, the speed [m/s] from which the approach braking stops the
        ego at ``(x, y)`` behind the road user ahead on its route among ``others (m, 5)``
        (:func:`~risk_env.highway.lanes.follow.leader_speed`); else inf."""
        if self.gate is None or not self._gate_on.leader_cap or self._leader_route is None:
            return math.inf
        length = float(unwrapped_highway(self.env).vehicle.LENGTH)
        gap = leader_gap(self._leader_route, (x, y), others, length)
        return leader_speed(gap, self.gate.approach_braking * self.gate.accel)

    def highway_action(
        self, v: float, omega: float, speed: float, steering: float
    ) -> tuple[np.ndarray, float]:
        """Our ``(v [m/s], omega [rad/s])``, from the current ``speed`` [m/s] and ``steering``
        [rad], as highway-env's normalised action ``(2,)`` float32, and the steering angle [rad]
        it applies (:func:`risk_env.highway.control.highway_action`)."""
        base = unwrapped_highway(self.env)
        half_length = 0.5 * float(base.vehicle.LENGTH)
        return highway_action(v, omega, speed, steering, self.dt, half_length, base.action_type)

    def _begin_episode(self, base: Any) -> None:
        vehicle = base.vehicle
        if vehicle is None:
            raise ValueError("the env has no controlled vehicle: call env.reset() first")
        self._vehicle = vehicle
        if not self._ready:  # the map is the same at every reset
            self.predictor = highway_predictor(self._predictor_arg, self.env)
            gate = make_gate(self._gate_on or False, self.predictor, self.base_scenario, base)
            self.gate, self._agent_predictor = gate
            self._ready = True
        self.route = RoutePath.of_vehicle(base.road.network, vehicle, self.destination)
        follow = self.gate is not None and self._gate_on.follow and self._agent_predictor is not None
        capped = self.gate is not None and self._gate_on.leader_cap
        self._leader_route = Route(base.road.network, self.route.lanes) if follow or capped else None
        self.lane = 0
        if self.warm_up:
            args = (self.base_scenario, self.make_agent, self.slots, self._agent_predictor)
            self.build_time += prepare_route(self._agents, self.route, *args)
        for agent in self._agents.values():
            if hasattr(agent, "reset"):
                agent.reset()
        if self.gate is not None:
            self.gate.reset(self.route, self.base_scenario)
        self._tracks = np.zeros((0, 5))
        action = getattr(vehicle, "action", {}) or {}
        self._steering = float(action.get("steering", 0.0))
        self._omega = 0.0
        self._fresh = True
        self._last_solve, self.last_solves = None, []

    def _rows(self, observation: np.ndarray) -> np.ndarray:
        """``(V, 4)``: x [m], y [m], heading [rad], signed speed [m/s] of the present rows."""
        obs = np.asarray(observation, dtype=float)
        features = list(unwrapped_highway(self.env).observation_type.features)
        if obs.ndim != 2 or obs.shape[1] != len(features):
            raise ValueError(f"expected a Kinematics observation (V, {len(features)}), got shape {obs.shape}")
        col = {name: obs[:, features.index(name)] for name in ("presence", "x", "y", "vx", "vy", "heading")}
        present = col["presence"] > 0.5
        present[0] = True  # the observer itself
        h = col["heading"]
        speed = col["vx"] * np.cos(h) + col["vy"] * np.sin(h)
        return np.column_stack([col["x"], col["y"], h, speed])[present]

    def _advance(self, x: float, y: float) -> bool:
        """Hand over to the next lane when the current one ends; whether it did."""
        switched = False
        while self.lane < len(self.route.paths) - 1:
            path = self.route.paths[self.lane]
            if float(project(path, x, y)) < path.lambda_goal - self.switch_ahead:
                break
            self.lane += 1
            switched = True
        return switched

    def _scenario_for(self, lane: int) -> Scenario:
        if self.route is None:
            raise ValueError("no route yet: the adapter reads it at its first predict() of an episode")
        return lane_scenario(self.base_scenario, self.route.paths[lane])

    def _agent_for(self, lane: int) -> Any:
        self._scenario_for(lane)  # the route's check
        path, base = self.route.paths[lane], self.base_scenario
        return lane_agent(self._agents, path, base, self.make_agent, self.slots, self._agent_predictor)

    def _measure_others(self, rows: np.ndarray) -> np.ndarray:
        """Measurements ``(K, 5)`` of the other vehicles (:func:`risk_env.highway.tracking.measure`)."""
        self._tracks = measure(rows, self._tracks, self.dt)
        return self._tracks.copy()


__all__ = [
    "ADAPTER_DEFAULTS",
    "TRACK_GATE",
    "INTERSECTION_CONFIG",
    "IDMEgo",
    "IntersectionAdapter",
    "LaneIndex",
    "RoutePath",
    "VERSIONS",
    "lane_path",
    "make_intersection_env",
    "reached",
]
