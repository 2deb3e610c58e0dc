"""One intersection episode of one agent, recorded: the shared runner of the intersection commands.

:func:`run_chunk` runs a pool job (an agent, a predictor, some seeds) and keeps its env and driver
in the process between jobs; :func:`run_episode` drives one seeded episode and returns its row:
the outcome (collision and its kind, goal, timeout, deadlock, whether the ego left the road: off
every lane of highway-env's map, ``vehicle.on_road`` false, at some step's end) and per-step
arrays (the scored risk, each MPC step's wall and CPU time, whether every object slot was
occupied, whether the step built an NLP in its solve: :class:`~benchmarks.highway_agents.Builder`)
with the episode risk an SMPC with a budget spent by its own estimator and the steps whose fallback
was a manoeuvre (the rest of the fallback steps applied a soft plan), the steps the junction gate
was closed (``gate_steps``), and the CPU time of the driver's reset (where the adapter builds its
agents' NLPs, before the episode's first step).

**Collision kinds** (:func:`crash_kind`, from the simulator's states at the start of the step that
ended in the crash): with d the unit vector from the ego's centre to the centre of the vehicle it
hit (the crashed vehicle nearest the ego), the ego's closing speed is ``v_e . d`` and the other's
``-v_o . d`` (velocities along each heading). The ego *drove into* the vehicle when its closing
speed exceeds the other's; otherwise the vehicle *drove into the ego* (rear-ended, or hit while
stopped or yielding). An ego that stood (speed below :data:`STOPPED_SPEED`) drove into nothing:
a vehicle whose front swings into it while it reverses along a curve closes on it at a corner,
not at its centre.

**Deadlock** (:func:`deadlocked`): an episode without a collision or the goal whose ego was
stopped (speed below :data:`STOPPED_SPEED`) at every step's end over its last
:data:`DEADLOCK_WINDOW` seconds (a planner that froze, not one that was slow).

**Jammed** (:func:`jammed`): at an episode's end without a collision or the goal, some other vehicle
had stood inside the junction (on a lane from an ``ir*`` node, speed below :data:`STOPPED_SPEED`) at
every step's end over the last :data:`DEADLOCK_WINDOW` seconds: highway-env's traffic locked in the
junction (its yielding rule lets two vehicles each wait for the other, or two of them crashed into
each other there), which no driver can cross while it lasts.

**Behind a wreck** (:func:`wrecked`): at an episode's end without a collision or the goal, a vehicle
other than the ego that crashed (into another: the ego did not) stands on the ego's way, its centre
within :data:`WRECK_REACH` of the centre line of the ego's route ahead of it. highway-env never
clears a wreck, so the way stays blocked for the rest of the episode, whatever the ego does.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from benchmarks.agent_names import REFERENCES
from benchmarks.highway_agents import built_problems, make_driver, resolve

ENV_DEFAULTS: dict[str, float] = {"duration": 13.0, "spawn_probability": 0.6, "initial_vehicle_count": 10}
"""highway-env's own values of the intersection options the commands set (``duration`` [s],
``spawn_probability`` per step, ``initial_vehicle_count``)."""
STOPPED_SPEED = 0.1
"""Speed [m/s] below which the ego counts as stopped."""
DEADLOCK_WINDOW = 10.0
"""How long [s] the ego must have been stopped at an episode's end for a deadlock."""
WRECK_REACH = 2.5
"""Distance [m] from the ego's route's centre line within which a wreck's centre blocks the way: two
cars' half widths (highway-env's cars are 2 m wide) and 0.5 m."""
_CACHE: dict[tuple[Any, ...], tuple[Any, Any]] = {}


def env_config(args: argparse.Namespace) -> dict[str, Any]:
    """highway-env's config entries the options set: ``duration``, ``spawn_probability``,
    ``initial_vehicle_count``."""
    return {
        "duration": args.duration,
        "spawn_probability": args.spawn_probability,
        "initial_vehicle_count": args.initial_vehicles,
    }


def _states(base: Any) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Position and velocity (along the heading) of every vehicle, by identity."""
    out = {}
    for v in base.road.vehicles:
        vel = float(v.speed) * np.array([np.cos(v.heading), np.sin(v.heading)])
        out[id(v)] = (np.array(v.position, dtype=float), vel)
    return out


def crash_kind(base: Any, before: dict[int, tuple[np.ndarray, np.ndarray]]) -> str:
    """``"ego"`` (the ego drove into the vehicle) or ``"other"`` (it drove into the ego), from the
    states ``before`` the crash step (see the module docstring)."""
    ego = base.vehicle
    hit = [v for v in base.road.vehicles if v is not ego and v.crashed] or [
        v for v in base.road.vehicles if v is not ego
    ]
    other = min(hit, key=lambda v: float(np.hypot(*(v.position - ego.position))))
    p_e, v_e = before.get(id(ego), (np.array(ego.position), np.zeros(2)))
    if float(np.hypot(*v_e)) < STOPPED_SPEED:
        return "other"
    p_o, v_o = before.get(id(other), (np.array(other.position), np.zeros(2)))
    d = p_o - p_e
    d = d / max(float(np.hypot(*d)), 1e-9)
    return "ego" if float(v_e @ d) > float(-v_o @ d) else "other"


def deadlocked(
    times: np.ndarray,
    speeds: np.ndarray,
    collision: bool,
    goal: bool,
    window: float = DEADLOCK_WINDOW,
    stopped: float = STOPPED_SPEED,
) -> bool:
    """Whether an episode deadlocked: neither ``collision`` nor ``goal``, at least ``window`` [s]
    long, and the ego's ``speeds`` [m/s] below ``stopped`` at every one of its ``times`` [s]
    (increasing; each step's end, the start included) within ``window`` of the last."""
    times, speeds = np.asarray(times, dtype=float), np.abs(np.asarray(speeds, dtype=float))
    if collision or goal or times.size == 0 or times[-1] - times[0] < window - 1e-9:
        return False
    last = times >= times[-1] - window - 1e-9
    return bool(np.all(speeds[last] < stopped))


def standing_inside(base: Any, since: dict[int, float]) -> dict[int, float]:
    """For every vehicle other than the ego that stands inside the junction now (``base.time``), the
    time [s] since which it has at every step's end: its entry in ``since`` (the previous step's
    result), else now."""
    from risk_env.highway.route import JUNCTION_PREFIX

    now = float(base.time)
    return {
        id(v): since.get(id(v), now)
        for v in base.road.vehicles
        if v is not base.vehicle
        and str(v.lane_index[0]).startswith(JUNCTION_PREFIX)
        and abs(float(v.speed)) < STOPPED_SPEED
    }


def jammed(
    since: dict[int, float], end: float, collision: bool, goal: bool, window: float = DEADLOCK_WINDOW
) -> bool:
    """Whether the junction was jammed at an episode's ``end`` [s] (neither ``collision`` nor
    ``goal``): some vehicle of :func:`standing_inside`'s ``since`` has stood there for ``window`` [s]."""
    return not collision and not goal and any(end - t >= window - 1e-9 for t in since.values())


def wrecked(base: Any, destination: str, collision: bool, goal: bool) -> bool:
    """Whether a crashed vehicle other than the ego stands on the ego's way in ``base`` (the unwrapped
    env at an episode's end, neither ``collision`` nor ``goal``): its centre within :data:`WRECK_REACH`
    of the route from the ego's lane to ``destination``, from the ego on (False where there is no
    such route: an ego on a wrong exit has no way to block)."""
    from risk_env.highway.route import RoutePath

    wrecks = [v for v in base.road.vehicles if v is not base.vehicle and v.crashed]
    if collision or goal or not wrecks:
        return False
    ego = base.vehicle
    try:
        route = RoutePath.of_vehicle(base.road.network, ego, destination)
    except ValueError:
        return False
    start = route.progress(0, *map(float, ego.position[:2]))
    way = route.position(np.arange(start, float(np.sum(route.lengths)) + 1e-9, 1.0))
    return any(np.min(np.hypot(*(way - np.asarray(v.position[:2])).T)) <= WRECK_REACH for v in wrecks)


def run_episode(driver: Any, env: Any, seed: int, slots: int) -> dict[str, Any]:
    """One episode of ``driver`` in ``env`` from ``seed``; returns its row (see the module)."""
    from risk_env.highway.adapter import reached

    obs, _ = env.reset(seed=seed)
    cpu_start = time.process_time()
    if hasattr(driver, "reset"):
        driver.reset()  # the adapter prepares its agents here: every NLP of the route
    reset_cpu = time.process_time() - cpu_start
    base = env.unwrapped
    risks, walls, cpus, full, builds = [], [], [], [], []
    manoeuvres = 0
    times, speeds = [float(base.time)], [float(base.vehicle.speed)]
    off_road = 0
    inside: dict[int, float] = {}
    done, kind = False, ""
    while not done:
        known = built_problems()
        action, _ = driver.predict(obs)
        reports = [r for r in getattr(driver, "last_solves", []) if r is not None]
        if reports:
            walls.append(sum(r.solve_time for r in reports))
            cpus.append(sum(r.cpu_time for r in reports))
            full.append(len(driver.last_objects) >= slots)
            manoeuvres += any(getattr(r, "fallback", None) == "manoeuvre" for r in reports)
            constructed = getattr(getattr(driver, "make_agent", None), "built", set())
            builds.append(bool(built_problems() - known - constructed))
        before = _states(base)
        obs, _, terminated, truncated, info = env.step(action)
        risks.append(info["risk"])
        times.append(float(base.time))
        speeds.append(float(base.vehicle.speed))
        off_road += not base.vehicle.on_road
        inside = standing_inside(base, inside)
        done = terminated or truncated
        if base.vehicle.crashed and not kind:
            kind = crash_kind(base, before)
    crashed = bool(base.vehicle.crashed)
    goal = bool(reached(env, driver.destination))
    risks = np.array(risks)
    spent = driver.spent_risk() if hasattr(driver, "spent_risk") else float("nan")
    return {
        "seed": seed,
        "steps": len(risks),
        "time_s": float(base.time),
        "collision": crashed,
        "ego_into_vehicle": crashed and kind == "ego",
        "vehicle_into_ego": crashed and kind == "other",
        "goal": goal,
        "timeout": not crashed and not goal,
        "deadlock": deadlocked(np.array(times), np.array(speeds), crashed, goal),
        "jammed": jammed(inside, times[-1], crashed, goal),
        "wrecked": wrecked(base, driver.destination, crashed, goal),
        "final_speed": speeds[-1],
        "off_road": off_road > 0,
        "off_road_steps": off_road,
        "risk_mean": float(risks.mean()) if len(risks) else 0.0,
        "risk_steps": risks,
        "solve_times": np.array(walls),
        "cpu_times": np.array(cpus),
        "full": np.array(full, dtype=bool),
        "built": np.array(builds, dtype=bool),
        "mpc_steps": len(walls),
        "fallbacks": int(getattr(driver, "failures", 0)),
        "manoeuvres": manoeuvres,
        "reset_cpu_s": reset_cpu,
        "spent_risk": float(spent),
        "gate_steps": int(getattr(getattr(driver, "gate", None), "closed_steps", 0)),
    }


def make_env(args: argparse.Namespace, predictor: str) -> Any:
    """``intersection-v2`` (``--env``) with the options' config, wrapped in
    :class:`risk_env.highway.RiskCostWrapper` (exact risk, ``--severity``) scoring with
    ``predictor``."""
    from risk_env.highway import RiskCostWrapper, make_intersection_env
    from risk_env.highway.adapter import ADAPTER_DEFAULTS

    radii = {k: ADAPTER_DEFAULTS[k] for k in ("ego_radius", "object_radius")}
    return RiskCostWrapper(
        make_intersection_env(version=args.env, signals=getattr(args, "signals", False), **env_config(args)),
        uncertainty=args.uncertainty,
        estimator="exact",
        severity=args.severity,
        predictor=predictor,
        **radii,
    )


def run_chunk(job: tuple[str, str, list[int], argparse.Namespace]) -> list[dict[str, Any]]:
    """Episodes ``seeds`` of agent ``name`` planning with ``predictor`` (a pool job; the env and
    driver are kept per process). The risk is scored with the run's first predictor, the same for
    every agent."""
    name, predictor, seeds, args = job
    settings = tuple(sorted((k, repr(v)) for k, v in vars(args).items()))
    key = (name, predictor, settings)
    agent = resolve(name, args.severity, args.budget)
    if key not in _CACHE:
        env = make_env(args, args.predictor[0])
        _CACHE[key] = (env, make_driver(agent, env, args, predictor))
    env, driver = _CACHE[key]
    out = []
    for seed in seeds:
        row = run_episode(driver, env, seed, args.slots)
        row.update(agent=name, predictor="" if agent.kind in REFERENCES else predictor)
        if agent.budget is None:
            row["spent_risk"] = ""
        out.append(row)
    return out
