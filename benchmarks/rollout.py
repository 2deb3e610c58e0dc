"""One episode of one agent in ``RiskCrossing-v0``, summarised: the rollout loop every benchmark
shares (anything with SB3's ``predict`` runs in it), and the agents it knows by name.

    python -m benchmarks.rollout --agent smpc:exact --uncertainty medium --tolerance 1000
    python -m benchmarks.rollout --agent ppo:lagrangian --uncertainty high --motion sampled

Agents are named as in every command (:mod:`benchmarks.agent_names`: ``rmpc[:RISK]``,
``smpc[:RISK][:SEVERITY:TOLERANCE][:budget=B]``, ``ppo:VARIANT``); :func:`build` makes one for an
env, :func:`rollout` runs an episode and :meth:`EpisodeRecord.summary` says what happened in it.
The command prints that summary and writes nothing.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks import cli
from benchmarks.agent_names import PPO_VARIANTS, REFERENCES, RISKS, AgentName, parse_agent

AGENTS: dict[str, tuple[str, str]] = {
    f"{kind}:{variant}": (kind.upper(), variant) for kind, variants in RISKS.items() for variant in variants
} | {f"ppo:{variant}": ("PPO", variant) for variant in PPO_VARIANTS}
"""Every agent without a tolerance of its own -> (method, variant): the risk estimator of an MPC,
the training of a PPO policy."""

SCENE_AGENTS: dict[str, str] = {"ppo:lagrangian_two_crossing": "two_crossing"}
"""Agents that see every object slot of one scene (risk_env.scenario.scenes) and run there only: the PPO
policy trained with ``--scene two_crossing`` (its observation has that scene's slot count)."""


def available_agents(scene: str = "paper") -> list[str]:
    """The names of :data:`AGENTS` this installation can run in ``scene`` (PPO needs the ``rl``
    extra; an agent of :data:`SCENE_AGENTS` runs in its scene only)."""
    names = [a for a in AGENTS if SCENE_AGENTS.get(a, scene) == scene]
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        return [name for name in names if AGENTS[name][0] != "PPO"]
    return names


def build(agent: AgentName, env: gym.Env, seed: int = 0, **options: Any) -> Any:
    """The agent ``agent`` for ``env``'s scenario. An SMPC's own tolerance and severity must be
    the env's (the command builds the env for them); its budget becomes ``risk_budget``, with no
    per-step bound unless it names a tolerance."""
    if agent.budget is not None:
        options.setdefault("risk_budget", agent.budget)
        if agent.tolerance is None:
            options.setdefault("risk_tolerance", math.inf)
    return build_agent(agent.method, agent.variant, env, seed, **options)


def build_agent(method: str, variant: str, env: gym.Env, seed: int = 0, **options: Any) -> Any:
    """The agent ``(method, variant)`` of :data:`AGENTS` for ``env``'s scenario and tolerance."""
    if method == "PPO":
        from agents.ppo.policy import PPOAgent, shipped_model

        return PPOAgent.load(shipped_model(variant), scenario=env.unwrapped.scenario)
    from agents import RMPC, SMPC

    if method == "RMPC":
        return RMPC.from_env(env, risk=variant, **options)
    if method == "SMPC":
        return SMPC.from_env(env, risk=variant, seed=seed, **options)
    raise ValueError(f"unknown method {method!r}; expected RMPC, SMPC or PPO")


@dataclass
class EpisodeRecord:
    """What happened in one episode. Arrays over time steps k = 0..steps (states) or 0..steps-1."""

    ego: np.ndarray
    """(steps+1, 4) ego (c1 [m], c2 [m], theta [rad], v [m/s])."""
    object: np.ndarray
    """(steps+1, 4) the first object (c1, c2, theta, v)."""
    actions: np.ndarray
    """(steps, 2) applied (v [m/s], omega [rad/s])."""
    risk: np.ndarray
    """(steps,) $R_{k+1|k}$ as the env reported it."""
    path_error: np.ndarray
    """(steps+1, 4) $e_k$, the first at the start state."""
    distance: np.ndarray
    """(steps+1,) centre distance ego-object [m], the nearest object's."""
    solve_time: np.ndarray
    """(steps,) agent's solve (or predict) time [s]."""
    fallback: np.ndarray
    """(steps,) whether the agent's hard problem failed and a fallback level acted."""
    fallback_kind: np.ndarray
    """(steps,) which fallback level acted (``agents.FALLBACK_KINDS``), "" where none did."""
    collision: bool
    success: bool
    epsilon: float
    reports: list[Any] = field(default_factory=list)
    """(steps,) the agent's ``last_solve`` after each step (None for agents without one)."""
    info: dict[str, Any] = field(default_factory=dict)
    """The env's ``info`` after the last step (``episode_risk``: the episode's summed risk)."""
    objects: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 4)))
    """(steps+1, M, 4) every object (c1, c2, theta, v), zeros where absent (``info["objects"]``)."""
    risk_terms: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(steps, M) each object's share $R_i$ of ``risk``."""
    rewards: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(steps,) the env's reward."""
    unit: str = ""
    """The unit of ``risk`` and ``epsilon`` (the severity's: J, probability, injuries)."""

    @property
    def steps(self) -> int:
        return len(self.actions)

    @property
    def e_acc(self) -> float:
        r"""Accumulated path error $\sum_k \|e_k\|$ over the episode (paper Sec. VII)."""
        return float(np.linalg.norm(self.path_error, axis=1).sum())

    @property
    def d_min(self) -> float:
        """Smallest centre distance ego-object [m]."""
        return float(self.distance.min())

    @property
    def failures(self) -> int:
        """Steps where a fallback level acted (the hard problem gave no plan)."""
        return int(self.fallback.sum())

    def fallbacks(self, kind: str) -> int:
        """Steps where the fallback level ``kind`` (e.g. ``"soft"``, ``"manoeuvre"``) acted."""
        return int(np.sum(self.fallback_kind == kind))

    @property
    def episode_return(self) -> float:
        """The sum of the env's rewards."""
        return float(self.rewards.sum())

    def summary(self) -> str:
        """What happened in the episode, in one line: steps, smallest distance, largest risk,
        goal, collision, path error and return."""
        unit = f" {self.unit}" if self.unit else ""
        return (
            f"{self.steps} steps: smallest distance {self.d_min:.2f} m, largest risk"
            f" {self.risk.max(initial=0.0):.4g}{unit} (epsilon {self.epsilon:g}{unit}),"
            f" goal {'reached' if self.success else 'not reached'},"
            f" {'a collision' if self.collision else 'no collision'}, e_acc {self.e_acc:.1f},"
            f" return {self.episode_return:.1f}"
        )

    @property
    def violation_rate(self) -> float:
        r"""Share of steps whose reported risk exceeded $\epsilon$ (by more than 1e-6 relative)."""
        return float(np.mean(self.risk > self.epsilon * (1 + 1e-6) + 1e-9)) if self.steps else 0.0


def rollout(agent: Any, env: gym.Env, seed: int | None = None) -> EpisodeRecord:
    """Run one episode of ``agent`` (anything with ``predict(obs) -> (action, state)``) in ``env``."""
    from risk_env.risk.severity import make_severity

    obs, info = env.reset(seed=seed)
    if hasattr(agent, "reset"):
        agent.reset()
    ego, obj, objects, terms = [info["ego"]], [info["object"]], [info["objects"]], []
    errors, dist = [info["path_error"]], [info["distance"]]
    actions, risks, times, kinds, reports, rewards = [], [], [], [], [], []
    state, start = None, True
    terminated = truncated = False
    while not (terminated or truncated):
        t0 = time.perf_counter()
        action, state = agent.predict(obs, state=state, episode_start=np.array([start]), deterministic=True)
        elapsed = time.perf_counter() - t0
        start = False
        report = getattr(agent, "last_solve", None)
        reports.append(report)
        times.append(getattr(report, "solve_time", elapsed) if report is not None else elapsed)
        kinds.append(str(getattr(report, "fallback", None) or ""))
        obs, reward, terminated, truncated, info = env.step(action)
        rewards.append(float(reward))
        actions.append(np.asarray(action, dtype=float).reshape(2))
        risks.append(info["risk"])
        ego.append(info["ego"])
        obj.append(info["object"])
        objects.append(info["objects"])
        terms.append(info["risk_terms"])
        errors.append(info["path_error"])
        dist.append(info["distance"])
    return EpisodeRecord(
        ego=np.array(ego),
        object=np.array(obj),
        actions=np.array(actions).reshape(-1, 2),
        risk=np.array(risks),
        path_error=np.array(errors),
        distance=np.array(dist),
        solve_time=np.array(times),
        fallback=np.array([k != "" for k in kinds], dtype=bool),
        fallback_kind=np.array(kinds, dtype=object),
        collision=bool(info.get("collision", False)),
        success=bool(info.get("is_success", False)),
        epsilon=float(env.unwrapped.scenario.risk_tolerance),
        reports=reports,
        info=info,
        objects=np.array(objects),
        risk_terms=np.array(terms).reshape(-1, len(objects[0])),
        rewards=np.array(rewards),
        unit=make_severity(env.unwrapped.scenario).unit,
    )


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.rollout``."""
    from risk_env.scenario.scenario import SCENE_NAMES, SEVERITY_NAMES, UNCERTAINTY_PRESETS

    p = cli.parser("rollout", __doc__)
    p.add_argument("--agent", default="smpc:exact", help="the agent (benchmarks.agent_names)")
    p.add_argument("--uncertainty", choices=UNCERTAINTY_PRESETS, default="medium", help="Table I level")
    p.add_argument(
        "--tolerance",
        type=cli.nonnegative_float,
        default=0.0,
        help="epsilon in the severity's unit (an SMPC that names its own overrides it)",
    )
    p.add_argument("--severity", choices=SEVERITY_NAMES, default="paper", help="severity model")
    p.add_argument("--motion", choices=("paper", "sampled"), default="paper", help="the object's motion")
    p.add_argument("--scene", choices=SCENE_NAMES, default="paper", help="which road users cross")
    p.add_argument("--seed", type=cli.nonnegative_int, default=0, help="the episode's seed")
    return p


def main(argv: list[str] | None = None) -> EpisodeRecord:
    """Run the episode the command line names and print its summary."""
    p = build_parser()
    args = p.parse_args(argv)
    try:
        agent = parse_agent(args.agent).with_defaults(args.severity, args.tolerance)
        if agent.kind in REFERENCES:
            raise ValueError(
                f"{agent.kind} drives in highway-env only (python -m benchmarks.highway_intersection)"
            )
        from risk_env.risk.severity import check_tolerance

        check_tolerance(args.tolerance, args.severity, "--tolerance")
    except ValueError as error:
        p.error(f"argument --agent: {error}" if "tolerance" not in str(error) else str(error))
    import risk_env  # noqa: F401  (registers the env)

    env = gym.make(
        "RiskCrossing-v0",
        uncertainty=args.uncertainty,
        risk_tolerance=agent.tolerance if agent.tolerance is not None else args.tolerance,
        severity=agent.severity or args.severity,
        object_motion=args.motion,
        scene=args.scene,
    )
    options = {"max_solve_time": math.inf} if agent.is_mpc else {}
    record = rollout(build(agent, env, args.seed, **options), env, seed=args.seed)
    env.close()
    print(f"{agent}, {args.uncertainty} uncertainty, seed {args.seed}: {record.summary()}")
    return record


if __name__ == "__main__":
    main()
