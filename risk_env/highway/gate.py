r"""The junction gate: a virtual stop line before the intersection (as industrial planners make stop
decisions), so that the ego waits *before* the junction rather than in it.

With a horizon of N T = 3 s the MPC enters the junction when the next 3 s look clear, meets
crossing traffic inside it, brakes and stops in a conflict zone, where highway-env's traffic
(which does not avoid a stopped car in a crossing lane) drives into it. The gate decides before the
junction, each step, whether the ego can cross all of it first:

- **The conflict zone** is the ego's route inside the junction: its lanes from a node
  ``ir*`` (highway-env's intersection entry) to the next, sampled every metre,
  $s_{in} \le s_j \le s_{out}$.
- **The ego** is at point $j$ from $t^e_{in,j}$, when its centre comes within
  :data:`GATE_CLEARANCE` of it, to $t^e_{out,j}$, when its centre is that far past it, driving from
  its speed at its largest acceleration ``accel`` up to ``speed_cap`` (the planner's $v_{ref}$
  there).
- **Each predicted mode** of another vehicle, of weight at least :data:`GATE_THRESHOLD`, occupies
  point $j$ from $t^o_{in,j}$ to $t^o_{out,j}$: the first and the last time its truncation box (the
  interval predictor's fast and slow runs bound it ahead and behind; or its mean car,
  :mod:`~risk_env.highway.gate_judge`) is within :data:`GATE_CLEARANCE` of it, over a horizon long
  enough for the ego to cross (at most :data:`GATE_STEPS` steps), linearly between steps; still
  there at the horizon's end: for ever.
- The gate **closes** when some mode occupies some point while the ego would be there, with
  :data:`GATE_MARGIN` to spare on either side: $\max(t^o_{in,j} - t^e_{out,j}, t^e_{in,j} -
  t^o_{out,j}) <$ margin. (Judged by arrival alone, $t^o_{in,j} < t^e_{out,j}$ + margin, it also
  closed for a vehicle that had passed a point long before the ego would come, a leader on the
  ego's own route included.) Then the MPC is handed a **virtual stationary object** at the stop
  line (:meth:`JunctionGate.virtual`), in one of its object slots, which its risk rows keep it off
  like any vehicle (no change to the problem).
- The ego **commits** once, the gate open, it cannot stop its front before the junction at
  ``accel`` ($v^2 / 2a$ beyond the distance left), or once its front is past the line: from then on
  the gate stays open this episode. A gate that closes when the ego can no longer stop before the
  line stays closed: the MPC brakes as hard as it can, and an ego that stopped past the line is held
  where it is until the gate opens: the virtual object moved :data:`HOLD_GAP` ahead of its disc as
  the hold begins, then never behind the disc, but no farther (an ego that creeps into it gets no new
  gap, so the slow approach's speed falls to 0). With ``hard_stop`` the adapter applies no more than
  that speed either (:meth:`JunctionGate.allowed_speed`): the slow approach bounds the plan's
  reference, the hard stop what is applied, a soft plan's or a fallback manoeuvre's. (Committing
  once the ego's centre passed the virtual object, measured on seeds 0-9, let soft plans push
  through it into the junction: 1 and 3 collisions for the RMPC and SMPC.)

The virtual object is predicted standing still with the spread :data:`VIRTUAL_SIGMA`, truncated at
:data:`VIRTUAL_HALF` (:class:`GatePredictor`): its risk is exactly 0 while the ego's disc stays
:data:`VIRTUAL_HALF` clear of its disc. A soft plan that brakes too late does come closer, and an
SMPC charges its budget the whole risk of the applied step: :meth:`JunctionGate.refund` gives the
virtual object's share back (measured: on SMPC seed 0 it was 1.137 of the 1.138 spent). The scored
risk (:class:`~risk_env.highway.RiskCostWrapper`) sees highway-env's vehicles only.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from risk_env import checks
from risk_env.highway.common import unwrapped_highway
from risk_env.highway.gate_judge import (
    GATE_CLEARANCE,
    GATE_MARGIN,
    GATE_THRESHOLD,
    JUDGES,
    MODE_JUDGES,
    GateDecision,
    GateSettings,
    check_gate,
    conflict_chance,
    mode_conflict,
    travel_time,
)
from risk_env.highway.lane_agents import lane_scenario
from risk_env.highway.lanes.predictor import EgoPlan, LanePredictor
from risk_env.highway.lanes.rollout import Rollout, roll_out
from risk_env.highway.predictors import (
    MATCH,
    SIGNAL_MATCH,
    VIRTUAL_HALF,
    VIRTUAL_SIGMA,
    GateError,
    GatePredictor,
    is_virtual,
    standing,
)
from risk_env.highway.route import JUNCTION_PREFIX, RoutePath, junction_span
from risk_env.prediction.mixture import Mixture
from risk_env.prediction.predictors import ConstantPredictor, Predictor
from risk_env.scenario.scenario import Scenario

__all__ = [
    "HOLD_GAP",
    "JUNCTION_PREFIX",
    "LINE_BUFFER",
    "MATCH",
    "SIGNAL_MATCH",
    "VIRTUAL_HALF",
    "VIRTUAL_SIGMA",
    "GateDecision",
    "GateError",
    "GatePredictor",
    "JunctionGate",
    "check_gate",
    "is_virtual",
    "junction_span",
    "make_gate",
    "standing",
    "travel_time",
]

GATE_STEPS = 20
"""Most prediction steps the gate looks ahead (10 s at T = 0.5 s)."""
GATE_RANGE = 40.0
"""Distance [m] of the ego to the junction within which the gate judges (farther: open)."""
LINE_BUFFER = 1.5
"""How far [m] before the line the virtual object stops the ego's front (the plan brakes late and
highway-env's car lags it)."""
HOLD_GAP = 0.5
"""Gap [m] between the ego's disc and the virtual object when it holds an ego past the line."""


class JunctionGate:
    """The gate of one route (see the module). ``predictor``: how the other vehicles are
    predicted (any :class:`~risk_env.prediction.Predictor`); ``reach`` [m]: the ego's and an object's
    radii summed; ``accel`` [m/s^2]: the ego's acceleration (also its braking, to commit);
    ``half_length`` [m]: half the ego car's length
    (its front stops at the line); ``dt`` [s]: the prediction step."""

    def __init__(
        self,
        predictor: Predictor,
        reach: float,
        accel: float,
        half_length: float,
        dt: float,
        margin: float = GATE_MARGIN,
        threshold: float = GATE_THRESHOLD,
        given_ego: bool = False,
        judge: str = "boxes",
        tolerance: float = 0.0,
        slow_approach: bool = False,
        hard_stop: bool = False,
        approach_braking: float = 0.5,
        keep_open: str | None = None,
        passage: bool = False,
    ) -> None:
        for name, value in (("reach", reach), ("accel", accel), ("half_length", half_length), ("dt", dt)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise GateError(f"{name} must be a finite number > 0, got {value!r}")
        if not (isinstance(margin, (int, float)) and math.isfinite(margin) and margin >= 0):
            raise GateError(f"margin must be a finite number >= 0 [s], got {margin!r}")
        if not (isinstance(threshold, (int, float)) and 0.0 <= threshold <= 1.0):
            raise GateError(f"threshold must lie in [0, 1], got {threshold!r}")
        self.predictor = predictor
        self.reach, self.accel, self.speed_cap = float(reach), float(accel), math.inf
        self.half_length, self.dt = float(half_length), float(dt)
        self.margin, self.threshold = float(margin), float(threshold)
        self.judge = checks.text("judge", judge, JUDGES)
        """How a mode is judged (:mod:`~risk_env.highway.gate_judge`)."""
        self.passage = bool(passage)
        """Whether the ego drives a passage the rollout verified (:attr:`GateSettings.passage`)."""
        rolls = "rollout judge" if self.judge == "rollout" else "verified passage" if passage else None
        if rolls and not (isinstance(predictor, LanePredictor) and predictor.ego):
            raise GateError(f"the {rolls} needs the lane+interval predictor with an ego")
        if not (isinstance(tolerance, (int, float)) and 0.0 <= tolerance < 1.0):
            raise GateError(f"tolerance must lie in [0, 1), got {tolerance!r}")
        self.tolerance = float(tolerance)
        """The chance of a conflict the gate accepts (0: none, every counted mode)."""
        if self.judge == "rollout" and tolerance:
            raise GateError(f"the rollout judge accepts no chance of a conflict, got tolerance={tolerance!r}")
        self.keep_open = None if keep_open is None else checks.text("keep_open", keep_open, MODE_JUDGES)
        """The judge by which an open gate closes again (None: :attr:`judge`; GateSettings.keep_open)."""
        if self.judge == "rollout" and keep_open is not None:
            raise GateError(
                f"the rollout judge judges no mode to keep a gate open, got keep_open={keep_open!r}"
            )
        self.verified_speed: float | None = None
        """This step's speed cap [m/s] of the passage the rollout verified, or None (not verified)."""
        self._rolled: Rollout | None = None
        self.given_ego = bool(given_ego)
        """Whether the others are predicted given that the ego goes (:meth:`_predict`)."""
        self.slow_approach = bool(slow_approach)
        """Whether a closed gate caps the agents' reference speed (:meth:`stop_speed`)."""
        self.hard_stop = bool(hard_stop)
        """Whether a closed gate clips the applied speed (:meth:`allowed_speed`)."""
        if not (isinstance(approach_braking, (int, float)) and 0.0 < approach_braking <= 1.0):
            raise GateError(f"approach_braking must lie in (0, 1], got {approach_braking!r}")
        self.approach_braking = float(approach_braking)
        """The share of ``accel`` the slow approach and the hard stop brake with (:meth:`stop_speed`)."""
        self.clearance = min(self.reach, GATE_CLEARANCE)
        """Distance [m] from the ego's path within which a vehicle is in conflict (and past which
        the ego's centre has cleared a point)."""
        self.route: RoutePath | None = None
        self.span: tuple[float, float] | None = None
        self.committed = False
        self.closed_steps = 0
        """Steps this episode the gate was closed."""
        self.last = GateDecision(False, False)
        self._progress = self._held = -math.inf
        self._was_closed = self._taken = False
        self.refunded = 0.0
        """Risk charged to an SMPC's budget for the virtual object and given back (:meth:`refund`)."""
        self.wrapper: GatePredictor | None = None
        """The agents' predictor the gate tells its virtual object (:meth:`step`), if any."""

    def reset(self, route: RoutePath, scenario: Scenario) -> None:
        """A new episode on ``route``: its conflict zone, not committed; the ego's speed through it
        :attr:`speed_cap`, the lowest $v_{ref}$ of ``scenario`` re-posed on the route's lanes (the
        planner's speed there)."""
        self.route, self.span = route, junction_span(route)
        self.speed_cap = min(lane_scenario(scenario, path).ego.v_ref for path in route.paths)
        self.committed, self.closed_steps, self._taken = False, 0, False
        self._progress = self._held = -math.inf
        self.last = GateDecision(False, self.span is None)

    def decide(
        self, progress: float, speed: float, others: np.ndarray, signals: list | None = None
    ) -> GateDecision:
        """The verdict for the ego at route arc length ``progress`` [m] and ``speed`` [m/s], the
        other vehicles measured as ``others (m, 5)``, with their observed turn signals (``signals``,
        one ``(2,)`` or None each, for the lane predictor) if any."""
        self._was_closed, self._rolled = self.last.closed, None
        if self.span is None or self.committed:
            self.last = GateDecision(False, True)
            return self.last
        s_in, s_out = self.span
        left = s_in - self.half_length - progress  # the centre's distance to its stop
        # an ego that can no longer stop (or is past the line) commits only if the gate let it come,
        # else it brakes as hard as it can and is held where it stops (the virtual object ahead)
        cannot_stop = left < 0.0 or max(speed, 0.0) ** 2 / (2.0 * self.accel) > left
        self._progress = float(progress)
        if cannot_stop and not self.last.closed:
            self.committed = True
            self.last = GateDecision(False, True)
            return self.last
        if left > GATE_RANGE or not len(others):
            self.last, self._taken = GateDecision(False, False), False
            return self.last
        if self.judge == "rollout":  # the scene rolled out with the ego going (lanes.rollout)
            self._rolled = roll_out(self.predictor, np.asarray(others, dtype=float), self._plan(), signals)
            through = self._rolled.through
            self.closed_steps += not through
            self.last = GateDecision(not through, False, math.inf if through else -math.inf)
            return self.last
        s = np.arange(s_in, s_out + 1e-9, 1.0)
        points = self.route.position(s)
        ego_in = travel_time(s - self.clearance - progress, speed, self.accel, self.speed_cap)
        ego_out = travel_time(s + self.clearance - progress, speed, self.accel, self.speed_cap)
        steps = min(GATE_STEPS, math.ceil((float(ego_out.max()) + self.margin) / self.dt))
        slack, masses = math.inf, []
        judge = self.keep_open if self._taken and self.keep_open is not None else self.judge
        for mixture in self._predict(np.asarray(others, dtype=float), steps, signals):
            mass = 0.0
            for mode in mixture.above(self.threshold):
                apart, share = mode_conflict(
                    mode, judge, points, self.clearance, self.dt, ego_in, ego_out, self.margin
                )
                slack = min(slack, apart)
                mass += mode.weight * share
            masses.append(mass)
        chance = conflict_chance(masses)
        closed = slack < self.margin if self.tolerance == 0.0 else chance > self.tolerance
        self.closed_steps += closed
        self.last, self._taken = GateDecision(closed, False, slack), not closed
        return self.last

    def _predict(self, others: np.ndarray, steps: int, signals: list | None = None) -> list[Mixture]:
        """The others' mixtures: given that the ego goes now (its route, ``accel`` up to
        :attr:`speed_cap`), where the predictor can condition on the ego (the lane predictor with the
        interval prediction and an ego, :class:`~risk_env.highway.lanes.predictor.EgoPlan`), so that
        traffic that would follow the ego into its exit brakes behind it, as highway-env's does."""
        if not isinstance(self.predictor, LanePredictor):
            return self.predictor.predict_scene(others, steps)
        plan = self._plan() if self.given_ego and self.predictor.ego is not None else None
        return self.predictor.predict_scene(others, steps, signals=signals, ego_plan=plan)

    def _plan(self) -> EgoPlan:
        """The ego going now: along its route, at ``accel`` up to :attr:`speed_cap`."""
        return EgoPlan(tuple(self.route.lanes), self.accel, self.speed_cap)

    def step(
        self, progress: float, speed: float, others: np.ndarray, signals: list | None = None
    ) -> np.ndarray:
        """:meth:`decide`, and the objects the MPC gets from the gate ``(0 or 1, 5)``: the virtual
        object when closed; the agents' :class:`GatePredictor` (:attr:`wrapper`) is told which, and
        the observed turn signals ``signals`` of ``others`` (or None)."""
        virtual = self.virtual() if self.decide(progress, speed, others, signals).closed else None
        self.verified_speed = None if virtual is not None else self._verify(progress, others, signals)
        if self.wrapper is not None:
            self.wrapper.virtual = virtual
            self.wrapper.signals = None if signals is None else (np.asarray(others, dtype=float), signals)
            going = self.given_ego and virtual is None and self.route is not None
            self.wrapper.ego_plan = self._plan() if going else None
        return np.zeros((0, 5)) if virtual is None else virtual[None]

    def _verify(self, progress: float, others: np.ndarray, signals: list | None) -> float | None:
        """With :attr:`passage`, from the gate's range until the ego's rear leaves the junction: the
        runs' lowest speed one step on where the rollout has the ego come through, else None."""
        if not self.passage or self.span is None or not len(others):
            return None
        s_in, s_out = self.span
        if progress > s_out + self.half_length or s_in - self.half_length - progress > GATE_RANGE:
            return None
        verdict = self._rolled or roll_out(
            self.predictor, np.asarray(others, dtype=float), self._plan(), signals
        )
        return max(verdict.speed, 0.0) if verdict.through else None  # the IDM's braking may overshoot

    def _line(self) -> float:
        """Route arc length [m] of the virtual object."""
        return self.span[0] - self.half_length + self.reach - LINE_BUFFER

    def refund(self, agent: Any, report: Any) -> float:
        """Give back to ``agent`` (an SMPC with a budget) the risk its last step (``report``) charged for
        the virtual object (slot 0, one mode: risk row 0 of the report's ``risk_fn``, the agent's
        own risk of the applied step); the amount, through :meth:`agents.mpc.smpc.SMPC.refund`."""
        if not self.last.closed or report is None or getattr(agent, "risk_budget", None) is None:
            return 0.0
        risk_fn = report.risk_fn
        ego_states, futures, data = risk_fn.args
        only = [f if row == 0 else None for row, f in enumerate(futures)]
        charged = float(np.asarray(risk_fn.func(ego_states, only, data))[0])
        agent.refund(min(charged, agent.spent_risk()))
        self.refunded += charged
        return charged

    def stop_speed(self) -> float:
        r"""With :attr:`slow_approach` and the gate closed, the highest speed [m/s] from which half the
        ego's largest braking (:attr:`approach_braking`) stops it where its disc meets the virtual
        object, $\sqrt{a d}$ ($d$ [m] the distance left; 0 past it); else inf. The MPC's horizon has
        no terminal row: without the cap it comes on at its reference speed until it can no longer
        stop before the line. On a verified passage: :attr:`verified_speed`."""
        if self.verified_speed is not None:
            return self.verified_speed
        if not (self.slow_approach and self.last.closed):
            return math.inf
        return self._line_speed()

    def allowed_speed(self, v: float) -> float:
        r"""The speed [m/s] to apply for the agent's ``v``: with :attr:`hard_stop` and the gate closed, at
        most $\sqrt{a d}$ (as :meth:`stop_speed`), so that whatever the agent chose (a soft plan that
        trades the virtual object's risk for another's, a fallback manoeuvre ranked by all objects
        alike) the ego stops where its disc meets the virtual object; on a verified passage at most
        :attr:`verified_speed`; else ``v``."""
        if self.verified_speed is not None:
            return min(v, self.verified_speed)
        if not (self.hard_stop and self.last.closed):
            return v
        return min(v, self._line_speed())

    def _line_speed(self) -> float:
        braking = self.approach_braking * self.accel  # v^2 = 2 b a d
        return math.sqrt(2.0 * braking * max(self._held - self._touch(), 0.0))

    def _touch(self) -> float:
        """Route arc length [m] where the virtual object would touch the ego's disc now."""
        return self._progress + self.reach + VIRTUAL_HALF

    def virtual(self) -> np.ndarray:
        """The virtual object's measurement ``(5,)``: standing on the ego's route where the ego's disc
        touches it with the ego's front :data:`LINE_BUFFER` before the junction's entry, heading along
        the route."""
        line, touch = self._line(), self._touch()
        s = max(line, self._held)
        if s < touch:  # it would touch the ego: hold the ego here
            # with a gap only as the hold begins: a gap at every step let a creeping ego push the object
            # on, half a metre at a time, into the junction's traffic
            holding = self._was_closed and self._held > line
            s = touch + (0.0 if holding else HOLD_GAP)
        self._held = s
        x, y = self.route.position(np.array([s]))[0]
        ahead = self.route.position(np.array([s + 0.5]))[0]
        return np.array([x, y, math.atan2(ahead[1] - y, ahead[0] - x), 0.0, 0.0])


def make_gate(
    on: bool | GateSettings, predictor: Predictor | None, scenario: Scenario, env: Any
) -> tuple[JunctionGate | None, Predictor | None]:
    """``(gate, the agents' predictor)`` for the adapter: off (``on`` False): ``(None, predictor)``;
    on (True, or its :class:`~risk_env.highway.gate_judge.GateSettings`): the gate judging with
    ``predictor`` (the paper's for None), the ego's numbers from ``scenario`` and the env's
    controlled vehicle, and ``predictor`` wrapped in :class:`GatePredictor` (None stays None: the
    paper's prediction keeps the virtual object standing, v = 0 and omega = 0, with its spread
    growing)."""
    settings = check_gate(on)
    if settings is None:
        return None, predictor
    judge = ConstantPredictor(scenario) if predictor is None else predictor
    ego = scenario.ego
    obj = scenario.objects[0]  # the touch distance along the lane, of the bodies' outer discs
    reach = ego.radius + obj.radius + max(map(abs, ego.disc_offsets)) + max(map(abs, obj.disc_offsets))
    length = float(unwrapped_highway(env).vehicle.LENGTH)
    options = dataclasses.asdict(settings)
    clearance = options.pop("clearance")
    for adapters in ("follow", "leader_cap"):  # the adapter's
        options.pop(adapters)
    gate = JunctionGate(judge, reach, ego.accel_max, 0.5 * length, scenario.dt, **options)
    gate.clearance = min(gate.reach, checks.positive("GateSettings.clearance", clearance))
    gate.wrapper = None if predictor is None else GatePredictor(predictor)
    return gate, gate.wrapper
