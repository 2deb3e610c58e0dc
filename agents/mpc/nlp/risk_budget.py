r"""The SMPC's episode risk budget and its risk weight: checks, the per-step bound a budget implies,
and the solver parameters of both (the NLP's rows are in :mod:`agents.mpc.nlp.ocp`).

**The budget** ``risk_budget=B`` [the severity's unit, per episode], spent in one of two ways
(:data:`ALLOCATIONS`).

*A share of what is left* (``"share"``, default). Step $k$'s risk rows get the tolerance
$\epsilon_k = \min(\epsilon, \alpha (B - \mathrm{spent}_k))$ with $\alpha$ = ``budget_share`` in
$(0, 1]$: every stage of the plan, $R_{n|k} \le \epsilon_k$, the paper's per-step constraint at a
level the episode sets. *Why it holds.* The step taken adds
$R_{1|k} \le \epsilon_k \le \alpha (B - \mathrm{spent}_k)$, so
$B - \mathrm{spent}_{k+1} \ge (1 - \alpha)(B - \mathrm{spent}_k) \ge 0$: the episode's summed risk
stays within $B$ (and with $\alpha < 1$ never exhausts it). The plan charges the step what it
realises, $R_{1|k}$, and re-plans the rest: the later stages' risk, foreseen with the horizon's
growing uncertainty, is never realised as foreseen, and is not paid for in advance.

*The whole horizon* (``"horizon"``). At step $k$ the plan must satisfy

$$
\mathrm{spent}_k + \sum_{n=1}^{N} R_{n|k} \le B,
$$

where $R_{n|k}$ is the agent's own per-stage risk (the SMPC's risk expression: for the exact risk
:meth:`~risk_env.risk.estimators.ExactRisk.solver_risk`, never below the env's $R$) and
$\mathrm{spent}_k$ is the risk of the steps already taken: the sum, since the episode began, of
each applied action's one-step risk $R_{1|j}$, $j < k$, by the same estimator (the env's $R$ at the
planned state 1, from the agent's own report; :meth:`agents.SMPC.spent_risk`). The agent still sees
only observations; spent restarts with the episode (a new episode is detected as the warm start
is: ``episode_start`` or an observation that does not continue the last one).

The sum across stages is carried stage-locally, the way the state carries the previous input: an
accumulator $c_n = \nu (R_1 + \dots + R_{n-1})$ ($c_1 = 0$, $c_{n+1} = c_n + \nu R_n$, a row of
stage $n$) and at stage $N$ the row $(B' - \mathrm{spent}_k - R_N)\, \nu - c_N \ge b$ ($b$ =
``backoff``, 1e-3 by default), with $\nu = 1/\mathrm{scale}$ (the severity's typical magnitude)
and $B'$ chosen so that the row holds iff $\mathrm{spent}_k + \sum_n R_n \le B - \mathrm{spare}$:
the plan keeps $\mathrm{spare} = b B + 10^{-6}\, \mathrm{scale}$ (:data:`RESOLUTION`) of the
budget unspent, so rounding of float32 observations and the solver's constraint tolerance of 1e-6
(in the row's units, the scale) cannot carry the episode over $B$. $B'$, $\mathrm{spent}_k$, $\nu$,
a switch-off and the weight are solver parameters (:data:`agents.mpc.nlp.parameters.TERMS`): one
built solver serves every budget.

*Why $\nu = 1/\mathrm{scale}$, not $1/B$.* Within one iteration fatrop (1.1.8) raises its primal
regularisation $\delta_w$, without limit, until every pivot of its Riccati factorisation passes a
relative test, and the inequalities' slacks are regularised too: a row (or a dynamics row) with
gradient $a$ adds $\delta_w a a^T$, so for every $\delta_w$ the pivots are those of $I + a a^T$,
about $1/|a|^2$ relative, and once $|a|$ is about a thousand they fail at any $\delta_w$;
$\delta_w$ overflows, the matrix turns to NaN, and the call never returns, whatever ``max_iter``
(:mod:`agents.mpc.nlp.calls`). With $\nu = 1/B$ and $B$ = 0.01 J under the paper's severity (scale
1000 J) the budget row's gradient was 1.5e4 (``RiskCrossing-v0`` medium, seed 20011: the first
call never returned); with $\nu = 1/\mathrm{scale}$ the budget row's and the accumulator's
gradients are the risk rows', about 1. Budgets below :data:`MIN_BUDGET` scales (the spare would
eat most of them) or above :data:`MAX_BUDGET` scales (whose row values lose the resolution) and
weights above :data:`MAX_WEIGHT` per scale are rejected.

*Why it holds.* If every step's hard problem is solved,
$\mathrm{spent}_{k+1} = \mathrm{spent}_k + R_{1|k} \le B - \sum_{n \ge 2} R_{n|k} \le B$, so the
episode's summed risk stays within $B$. A step whose plan misses the budget is a fallback (the
soft problem, whose budget row has its own L1-penalised slack, or a manoeuvre), counted as always:
the bound is promised for episodes without one.

*What it bounds.* With ``severity="probability"`` ($s = 1$) each $R_{k+1|k}$ is the probability of
a collision at step $k + 1$ given the history up to $k$. Assume (i) the prediction is the true
distribution of the next step (``object_motion="sampled"`` draws it from that very model) and (ii)
the risk counted is that of the step actually taken. Then, with $C_k$ the event "collision at step
$k$", Boole's inequality, then the tower rule and linearity of expectation give

$$
P(\text{any collision}) = P\Big(\bigcup_k C_k\Big) \le \sum_k P(C_k)
= \sum_k E\big[P(C_k \mid \text{history})\big] = E\Big[\sum_k R_{k|k-1}\Big]
= E[\text{episode risk}] \le B,
$$

since the episode risk is at most $B$ in every episode without a fallback. With ``"injury"``
($s$ = expected seriously injured people of a collision) the same steps without Boole's
inequality give: the expected number of serious injuries per episode is
$E[\sum_k I_{C_k} s_k] = E[\text{episode risk}] \le B$.

**Per-step bound.** The budget may stand alongside $\epsilon$ or instead of it:
``risk_tolerance=math.inf`` means no per-step bound of its own. Every $R_n$ is at most $B$ (all
are $\ge 0$), so the per-step rows are given $\epsilon_{eff} = \min(\epsilon, B + b\,
\mathrm{scale})$ (implied by the budget, they keep the rows' clearance form, which helps the
solver), and $B = 0$ is $\epsilon = 0$ exactly (the ``"zero"`` form keeps the disc off every
truncation box, so every $R_n$ is 0 and the budget row, switched off then, would be $0 \le 0$).

**The weight** ``risk_weight=w`` [cost per unit of the severity] adds $w \sum_{n=1}^{N} R_{n|k}$
to the objective, with or without a budget or a tolerance: a penalty to compare with the
constraint on equal terms. The RMPC takes neither: its worst case is no expectation.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from agents.mpc.nlp.parameters import TERMS
from risk_env import checks

ALLOCATIONS: tuple[str, ...] = ("share", "horizon")
r"""How an SMPC spends its episode budget: ``"share"`` (default), each step may spend a share $\alpha$
of what is left; ``"horizon"``, each plan fits its whole horizon's risk into what is left."""
BUDGET_SHARE = 0.5
r"""$\alpha$ by default: a step may spend half of what is left of the budget."""


def check_allocation(value: Any) -> str:
    """``budget_allocation``: one of :data:`ALLOCATIONS`."""
    if value not in ALLOCATIONS:
        raise ValueError(f"budget_allocation must be one of {ALLOCATIONS}, got {value!r}")
    return value


def check_share(value: Any) -> float:
    r"""``budget_share`` $\alpha$: a number in $(0, 1]$."""
    share = _nonnegative(value, "budget_share", "the share of the budget left a step may spend")
    if not 0.0 < share <= 1.0:
        raise ValueError(f"budget_share must lie in (0, 1], got {value!r}")
    return share


def share_tolerance(epsilon: float, budget: float, spent: float, share: float) -> float:
    r"""The step's tolerance under ``"share"``: $\min(\epsilon, \alpha (B - \mathrm{spent}))$, at least 0."""
    return max(0.0, min(epsilon, share * (budget - spent)))


RESOLUTION = 1e-6
"""The solvers' constraint tolerance in the budget row's units (the severity's scale): the plan keeps
this many scales of the budget unspent besides $b B$ ($b$ = ``backoff``)."""
MIN_BUDGET = 1e-5
"""The smallest budget $> 0$ [the severity's scale]: below it the spare would eat most of it."""
MAX_BUDGET = 1e6
"""The largest budget [the severity's scale]: the row's values keep a resolution of 1e-10 scales."""
MAX_WEIGHT = 1e6
"""The largest risk weight times the severity's scale [cost]. Heavier weights buy nothing but
harder problems (with the probability severity at medium uncertainty, seed 1: from 1e4 on, calls
run to their iteration limit and fallbacks act), and near 1e200 per scale the objective's Hessian
overflows: fatrop's inertia correction then never ends (:mod:`agents.mpc.nlp.calls`)."""


def check_budget(
    value: Any, name: str = "risk_budget", scale: float | None = None, unit: str = ""
) -> float | None:
    """``value`` as an episode risk budget: None, 0 or a finite number within [``MIN_BUDGET``,
    ``MAX_BUDGET``] times ``scale`` (the severity's; no range without it); else ``ValueError``
    naming it."""
    if value is None:
        return None
    budget = _nonnegative(value, name, "an episode risk budget [the severity's unit]")
    if scale is not None and budget > 0.0 and not MIN_BUDGET * scale <= budget <= MAX_BUDGET * scale:
        raise ValueError(
            f"{name} must be 0 or within [{MIN_BUDGET * scale:g}, {MAX_BUDGET * scale:g}] {unit}".rstrip()
            + f" ({MIN_BUDGET:g} to {MAX_BUDGET:g} times the severity's scale of {scale:g}), got {value!r}"
        )
    return budget


def check_weight(
    value: Any, name: str = "risk_weight", scale: float | None = None, unit: str = ""
) -> float | None:
    r"""``value`` as the risk weight of the objective: None, or a finite number $\ge 0$, at most
    ``MAX_WEIGHT / scale`` (no limit without ``scale``)."""
    if value is None:
        return None
    weight = _nonnegative(value, name, "a weight [cost per unit of the severity]")
    if scale is not None and weight * scale > MAX_WEIGHT:
        per = f" per {unit}" if unit else ""
        raise ValueError(
            f"{name} must be at most {MAX_WEIGHT / scale:g}{per} ({MAX_WEIGHT:g} over the severity's "
            f"scale of {scale:g}), got {value!r}"
        )
    return weight


def _nonnegative(value: Any, name: str, what: str) -> float:
    if not checks.is_real(value):  # a number of any real type; not a bool, not a string
        raise TypeError(f"{name} must be {what}, a finite number >= 0, got {checks.describe(value)}")
    number = float(value)
    if not (math.isfinite(number) and number >= 0.0):
        raise ValueError(f"{name} must be {what}, a finite number >= 0, got {value!r}")
    return number


def effective_tolerance(epsilon: float, budget: float | None, backoff: float, scale: float) -> float:
    r"""The per-step bound the risk rows are given: $\epsilon$ without a budget; with one,
    $\min(\epsilon, B + b\, \mathrm{scale})$ ($b$ = ``backoff``; implied by the budget), and 0 at $B = 0$."""
    if budget is None:
        return epsilon
    if budget <= 0.0:
        return 0.0
    return min(epsilon, budget + backoff * scale)


def terms_parameters(
    budget: float | None, spent: float, weight: float | None, scale: float = 1.0, backoff: float = 1e-3
) -> np.ndarray:
    r"""The :data:`agents.mpc.nlp.parameters.TERMS` solver parameters: ($B'$, spent,
    $\nu = 1/\mathrm{scale}$, switch-off, $w$), $B'$ such that the budget row
    $(B' - \mathrm{spent} - R_N)\, \nu - c_N \ge b$ ($b$ = ``backoff``) holds iff the plan's
    $\mathrm{spent} + \sum_n R_n \le B - b B - 10^{-6}\, \mathrm{scale}$ (:data:`RESOLUTION`); without
    a budget (or at $B = 0$, where $\epsilon = 0$ holds every $R_n$ at 0) the row is switched off."""
    on = budget is not None and budget > 0.0
    shifted = budget - backoff * budget - RESOLUTION * scale + backoff * scale if on else 0.0
    out = np.array(
        [shifted, spent, 1.0 / scale if on else 0.0, 0.0 if on else 1.0, weight or 0.0], dtype=float
    )
    assert out.size == TERMS
    return out
