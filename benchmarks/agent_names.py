r"""One way to name an agent, in every command and every result table.

The grammar (parts separated by colons; brackets: optional)::

    rmpc[:RISK]                                  RISK: worst_case (default) or grid
    smpc[:RISK][:SEVERITY:TOLERANCE][:budget=B]  RISK: exact (default) or monte_carlo
    ppo:VARIANT                                  a shipped policy: penalty, lagrangian, ...
    idm                                          highway-env's IDM driver (highway commands)
    hindsight                                    the best wait-then-go schedule in hindsight (highway)

``SEVERITY`` is one of :data:`risk_env.scenario.SEVERITY_NAMES` and ``TOLERANCE`` the per-step
bound $\epsilon$ in that severity's own unit (J, probability, injuries); ``budget=B`` gives the SMPC
an episode risk budget (``risk_budget=B``, :mod:`agents.mpc.nlp.risk_budget`), with no per-step bound
unless a tolerance is given too. A command that sweeps the tolerance itself (``table2``,
``sampled``, ``timing``) takes agents without one. Lists are comma-separated:
``--agents rmpc,smpc:paper:1000,idm``.

:func:`parse_agent` reads a name, :class:`AgentName` prints it in its full form (every part
spelled out: ``smpc`` is printed ``smpc:exact``), which is how the result tables name agents.
Spellings of earlier versions are refused with the new one (:data:`OLD_SPELLINGS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from risk_env.scenario.scenario import SEVERITY_NAMES

RISKS: dict[str, tuple[str, ...]] = {"rmpc": ("worst_case", "grid"), "smpc": ("exact", "monte_carlo")}
"""The risk estimators of each MPC; the first is the default."""
PPO_VARIANTS: tuple[str, ...] = ("penalty", "lagrangian", "lagrangian_two_crossing")
"""The shipped PPO policies (``agents/models/ppo_VARIANT.zip``)."""
KINDS: tuple[str, ...] = ("rmpc", "smpc", "ppo", "idm", "hindsight")
METHODS = {"rmpc": "RMPC", "smpc": "SMPC", "ppo": "PPO", "idm": "IDM", "hindsight": "hindsight"}
"""The class (or driver) each kind of agent is."""
REFERENCES: tuple[str, ...] = ("idm", "hindsight")
"""The kinds that are reference drivers, not our planners: no parts, no predictor, no solver; they
drive highway-env's vehicle themselves (highway commands only)."""
FORMS = {
    "rmpc": "rmpc[:RISK]",
    "smpc": "smpc[:RISK][:SEVERITY:TOLERANCE][:budget=B]",
    "ppo": "ppo:VARIANT",
    "idm": "idm",
    "hindsight": "hindsight",
}
"""The form of each kind's names."""
GRAMMAR = ", ".join(FORMS.values())
OLD_SPELLINGS: dict[str, str] = {
    "smpc0": "smpc:paper:0",
    "smpc1000": "smpc:paper:1000",
    "smpc_mc1000": "smpc:monte_carlo:paper:1000",
    "smpc_exact": "smpc:exact",
    "smpc_mc": "smpc:monte_carlo",
    "rmpc_grid": "rmpc:grid",
}
"""Names of earlier versions (``stress``, ``timing``) -> the same agent in this grammar."""


def number(x: float) -> str:
    """``x`` as the shortest text that reads back as ``x`` (``1000``, ``0.01``, ``inf``)."""
    short = f"{x:g}"
    return short if float(short) == x else repr(float(x))


@dataclass(frozen=True)
class AgentName:
    """A parsed agent name; ``str()`` gives its full form."""

    kind: str
    """``rmpc``, ``smpc``, ``ppo``, ``idm`` or ``hindsight``."""
    variant: str = ""
    """The risk estimator (MPCs) or the shipped policy (PPO); empty for ``idm`` and ``hindsight``."""
    severity: str | None = None
    """The SMPC's severity (None: the command's)."""
    tolerance: float | None = None
    r"""The SMPC's per-step bound $\epsilon$ in the severity's unit (None: the command's)."""
    budget: float | None = None
    """The SMPC's episode risk budget B (None: none)."""

    def __str__(self) -> str:
        parts = [self.kind] + ([self.variant] if self.variant else [])
        if self.severity is not None and self.tolerance is not None:
            parts += [self.severity, number(self.tolerance)]
        if self.budget is not None:
            parts.append(f"budget={number(self.budget)}")
        return ":".join(parts)

    @property
    def method(self) -> str:
        """``RMPC``, ``SMPC``, ``PPO`` or ``IDM``."""
        return METHODS[self.kind]

    @property
    def is_mpc(self) -> bool:
        return self.kind in RISKS

    def with_defaults(self, severity: str, tolerance: float) -> AgentName:
        """The SMPC with ``severity`` and ``tolerance`` where it names none (other agents as they are)."""
        if self.kind != "smpc" or self.severity is not None:
            return self
        return AgentName(self.kind, self.variant, severity, float(tolerance), self.budget)


def parse_agent(
    text: str, kinds: tuple[str, ...] = KINDS, tolerance: bool = True, budget: bool = True
) -> AgentName:
    """The agent named ``text`` (see the module). ``kinds``: the kinds the command runs;
    ``tolerance``/``budget``: whether the command takes an SMPC's own tolerance or budget. Raises
    ``ValueError`` saying what is wrong and what is valid."""
    name = text.strip()
    if name in OLD_SPELLINGS:
        raise ValueError(f"agent {name!r} is spelled {OLD_SPELLINGS[name]!r} now")
    kind, *parts = name.split(":")
    if kind not in kinds:
        valid = ", ".join(FORMS[k] for k in kinds)
        raise ValueError(f"unknown agent {name!r}: expected {valid}")
    if kind in REFERENCES:
        if parts:
            raise ValueError(f"agent {name!r}: {kind} takes no parts")
        return AgentName(kind)
    if kind == "ppo":
        if len(parts) != 1 or parts[0] not in PPO_VARIANTS:
            raise ValueError(
                f"agent {name!r}: expected ppo:VARIANT, VARIANT one of {', '.join(PPO_VARIANTS)}"
            )
        return AgentName("ppo", parts[0])
    risks = RISKS[kind]
    variant = parts.pop(0) if parts and parts[0] in risks else risks[0]
    spent: float | None = None
    if parts and parts[-1].startswith("budget="):
        if kind != "smpc" or not budget:
            where = "the RMPC has no risk budget" if kind == "rmpc" else "this command takes no budget"
            raise ValueError(f"agent {name!r}: {where}")
        spent = _value(parts.pop()[len("budget=") :], name, "budget")
    severity: str | None = None
    epsilon: float | None = None
    if parts:
        if kind == "rmpc":
            raise ValueError(
                f"agent {name!r}: expected rmpc[:RISK], RISK one of {', '.join(risks)}"
                " (the RMPC bounds the worst case and takes no tolerance)"
            )
        if len(parts) != 2 or parts[0] not in SEVERITY_NAMES:
            raise ValueError(
                f"agent {name!r}: expected smpc[:RISK][:SEVERITY:TOLERANCE][:budget=B], RISK one of"
                f" {', '.join(risks)}, SEVERITY one of {', '.join(SEVERITY_NAMES)}"
            )
        if not tolerance:
            raise ValueError(
                f"agent {name!r}: this command sweeps the tolerance itself; name the agent without"
                f" one, e.g. {kind}:{variant}"
            )
        severity = parts[0]
        epsilon = _value(parts[1], name, "tolerance")
        from risk_env.risk.severity import check_tolerance

        check_tolerance(epsilon, severity, f"agent {name!r}: the tolerance")
    if spent is not None and not (math.isfinite(spent) and spent >= 0):
        raise ValueError(f"agent {name!r}: the budget {spent!r} must be finite and >= 0")
    return AgentName(kind, variant, severity, epsilon, spent)


def _value(text: str, name: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"agent {name!r}: the {what} {text!r} is not a number") from None


def parse_agents(
    text: str, kinds: tuple[str, ...] = KINDS, tolerance: bool = True, budget: bool = True
) -> list[AgentName]:
    """The agents of a comma list (see :func:`parse_agent`); an empty list or a repeated agent is
    an error."""
    items = [item.strip() for item in text.split(",")]
    if not any(items):
        raise ValueError(f"expected a comma list of agents ({GRAMMAR}), got {text!r}")
    if "" in items:
        raise ValueError(f"empty item in the comma list {text!r}")
    agents = [parse_agent(item, kinds, tolerance, budget) for item in items]
    seen = [str(a) for a in agents]
    if len(set(seen)) != len(seen):
        raise ValueError(f"an agent is named twice in {text!r} ({', '.join(seen)})")
    return agents
