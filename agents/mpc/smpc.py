r"""The stochastic MPC (paper Sec. V): the expected-risk constraint $R_{n|k} \le \epsilon$,
$n = 1, \dots, N$."""

from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np

from agents.base import CallRecord, SolveReport
from agents.mpc.controller import PathFollowingMPC
from agents.mpc.nlp import risk_budget as rb
from agents.mpc.nlp.parameters import INACTIVE, NUMBER_COLUMNS
from agents.mpc.objects import slot_rows, symbolic
from risk_env import checks
from risk_env.models.ops import CASADI
from risk_env.prediction.belief import Belief
from risk_env.risk.bodies import BodyRisk
from risk_env.risk.estimators import ExactRisk, MonteCarloRisk, RiskEstimator
from risk_env.risk.severity import make_severity
from risk_env.scenario.scenario import Scenario

CLEARANCE_SOFTNESS = 0.05
r"""Temperature [m] of the soft minimum over the Monte Carlo draws' distances (the clearance): below
the nearest distance by at most ``CLEARANCE_SOFTNESS`` $\cdot \log J$ (0.31 m for $J = 500$)."""


class SMPC(PathFollowingMPC):
    r"""Path-following MPC under the expected risk $R = E[I_C s]$ of every prediction step
    $n = 1, \dots, N$.

    ``risk="exact"`` (default): :class:`risk_env.risk.estimators.ExactRisk`, deterministic and smooth.

    ``risk="monte_carlo"``: the paper's estimator, :class:`risk_env.risk.estimators.MonteCarloRisk`, over
    ``samples`` draws per step $n$ (default: the scenario's $J = 500$), drawn once per solve from the
    agent's own generator (``seed``; common random numbers across the solver's iterations,
    reproducible after :meth:`reset`) and passed as parameters. The solver sees the estimator's
    smoothed CasADi form (a logistic indicator of width ``bandwidth`` times the draws' spread, the
    severity's kinks rounded by ``severity_smoothing``; see :class:`~risk_env.risk.estimators.MonteCarloRisk`
    for the forms and their bias); ``smoothing`` [m] fixes the width instead. The reported risk
    re-evaluates the plan with the hard indicator on the same draws.

    The exact risk's constraint is written
    $\max(d - r, (\epsilon - R) / \mathrm{scale}) \ge \mathrm{backoff}$, with $d - r$ the clearance, and
    $d - r \ge \mathrm{backoff}$ alone at $\epsilon = 0$ (the core's ``"zero"`` variant). $R$ there is
    :meth:`~risk_env.risk.estimators.ExactRisk.solver_risk`: the env's quadrature cut at $\pm 5 \sigma$
    (54 nodes, not 66) with its bounded shortfall added back, never below the env's $R$ and above it by
    at most 5.7e-7 $E[s]$; its derivatives are those of the integral (see
    :func:`~risk_env.risk.estimators.disc_probability`), a third of the cost of differentiating the
    rule. The clearance $d - r$ is the distance $d$ from the ego centre to where the object may be,
    minus $r = r_e + r_o$: to the truncation box for the exact risk; to the draws for Monte Carlo, as a
    smooth soft minimum of the distances, below the nearest by at most :data:`CLEARANCE_SOFTNESS`
    $\cdot \log J$ (0.31 m for $J = 500$). $R$ vanishes wherever the clearance is positive (for
    bodies of several discs by the estimator's gate,
    :meth:`~risk_env.risk.bodies.BodyRisk.capsule_clearance`), so this is $R \le \epsilon$; but
    $R$'s gradient vanishes with $R$, and $R \le 0$ has no interior, which stalls an interior-point
    solver, while the clearance keeps a gradient (and a truncated Gaussian puts ~1e-20
    of mass near a box edge ten standard deviations out: the unguarded exact constraint would let the
    plan into the box at $\epsilon = 0$). So at $\epsilon = 0$ the exact SMPC is the RMPC's box
    constraint, as it must be ($P = 0$ off the box), and the Monte Carlo SMPC keeps off every draw (it
    differs from the RMPC by the tails its draws miss). The Monte Carlo SMPC at $\epsilon > 0$ asks
    $(\epsilon - R) / \mathrm{scale} \ge \mathrm{backoff}$ alone: its smoothed $R$ is never exactly 0,
    so the constraint has an interior, and the clearance could only matter for tolerances below the
    logistic's tails (a few J); it doubled the cost of an evaluation.

    Monte Carlo in the solver: with a fixed 0.05 m logistic the risk was a staircase of single
    draws where they are sparse (500 draws with $\sigma$ = 6 m lie ~0.1 m apart near the disc edge),
    and the paper's severity has a kink per draw in the ego speed, right where the SMPC puts it
    (kinetic energies matched): the solver cycled between kinks and failed on 2 of the paper's
    closed-loop steps. The spread-proportional width and the rounded severity halve the iterations
    and remove those failures. An episode's first step (a cold start) first solves the same SMPC
    with ``pilot_samples`` draws (default 100) from every rollout and then the full problem once,
    from the pilot's plan: about a third of the cost of three full cold solves. ``pilot_samples=None``
    solves the full problem from every rollout.

    **Many objects** ($K$ slots, :mod:`agents.mpc.objects`): one row per stage on the sum of the
    active slots' risks, $\sum_k R_k \le \epsilon$ (the expected total harm of the step), written
    $\max(\min_k (d_k - r_k), (\epsilon - \sum_k R_k) / \mathrm{scale}) \ge \mathrm{backoff}$ (each
    inactive slot's clearance lifted by :data:`agents.mpc.nlp.parameters.INACTIVE`, its $R$ times 0); at
    $\epsilon = 0$ one clearance row per slot. With one slot these are the single-object rows exactly.

    **Episode risk budget and risk weight** (:mod:`agents.mpc.nlp.risk_budget`, where the guarantee and its
    assumptions are written out): ``risk_budget=B`` bounds the summed risk of an episode without a
    fallback (``info["episode_risk"]``) by $B$, spent being the risk of the steps already taken
    (:meth:`spent_risk`). ``budget_allocation="share"`` (default) lets each step's rows use
    $\min(\epsilon, \alpha (B - \mathrm{spent}))$ (``budget_share`` $\alpha$, 0.5 by default): a step
    spends where it buys progress, and what is left never runs out; ``"horizon"`` asks every plan for
    $\mathrm{spent} + \sum_n R_{n|k} \le B$ (its whole horizon's foreseen risk, a stricter allocation). With
    ``severity="probability"`` a bound on the chance of any collision in the episode, with
    ``"injury"`` on the expected serious injuries per episode. ``risk_tolerance=math.inf`` drops
    the per-step bound (the budget alone). ``risk_weight=w`` adds $w \sum_n R_{n|k}$ to the
    objective, with or without either bound.

    The severity model is the scenario's (``scenario.severity``). See
    :class:`agents.mpc.controller.PathFollowingMPC` for the problem, solver options and the fallback (the soft
    problem, then the safest manoeuvre; counted in :attr:`failures`, never raised).
    """

    RISK_METHODS = ("exact", "monte_carlo")
    ZERO_TOLERANCE_VARIANT = True
    WEIGHTED = True

    def __init__(
        self,
        scenario: Scenario,
        risk: str = "exact",
        samples: int | None = None,
        bandwidth: float = 0.05,
        smoothing: float | None = None,
        severity_smoothing: float = 0.05,
        pilot_samples: int | None = 100,
        risk_budget: float | None = None,
        risk_weight: float | None = None,
        budget_allocation: str = "share",
        budget_share: float = rb.BUDGET_SHARE,
        **kwargs: Any,
    ) -> None:
        severity = make_severity(scenario) if isinstance(scenario, Scenario) else None
        scale, unit = (severity.scale, severity.unit) if severity is not None else (None, "")
        self.risk_budget = rb.check_budget(risk_budget, scale=scale, unit=unit)
        """$B$, the episode risk budget [the severity's unit] (None: none); fixed at construction."""
        self.budget_allocation = rb.check_allocation(budget_allocation)
        """How the budget is spent (:data:`agents.mpc.nlp.risk_budget.ALLOCATIONS`)."""
        self.budget_share = rb.check_share(budget_share)
        r"""$\alpha$, the share of what is left of the budget a step may spend (``"share"``)."""
        self.risk_weight = rb.check_weight(risk_weight, scale=scale, unit=unit)
        r"""$w$, the weight of $\sum_n R_{n|k}$ in the objective (None: none); fixed at construction."""
        self._spent: dict[int, float] = {}
        self._budget_backoff = checks.positive("backoff", kwargs.get("backoff", 1e-3), strict=False)
        if risk not in self.RISK_METHODS:
            raise ValueError(f"unknown SMPC risk method {risk!r}; expected one of {self.RISK_METHODS}")
        if samples is not None:
            samples = checks.integer("samples", samples, minimum=1)
        if pilot_samples is not None:
            pilot_samples = checks.integer("pilot_samples", pilot_samples, minimum=1)
        self.risk_method = risk
        self.pilot_samples = pilot_samples
        self._pilot: SMPC | None = None
        self._options = {
            "samples": samples,
            "bandwidth": bandwidth,
            "smoothing": smoothing,
            "severity_smoothing": severity_smoothing,
        }
        super().__init__(scenario, **kwargs)
        if risk == "monte_carlo" and pilot_samples and pilot_samples < self.estimator.samples:
            est = self.estimator
            options = {k: v for k, v in kwargs.items() if k not in ("risk_tolerance", "seed")}
            # the pilot plans a first guess only: without the budget's and the weight's terms;
            # at a positive tolerance (each call sets the agent's): its forms are "general"'s
            self._pilot = SMPC(
                scenario,
                risk="monte_carlo",
                risk_tolerance=min(est.severity.scale, est.severity.upper_bound),
                samples=pilot_samples,
                bandwidth=est.bandwidth,
                smoothing=est.smoothing,
                severity_smoothing=est.severity_smoothing,
                pilot_samples=None,
                seed=None if self.seed is None else self.seed + 1,
                **options,
            )
            self.build_time += self._pilot.build_time

    def _estimator(self, scenario: Scenario) -> RiskEstimator:
        if self.risk_method == "exact":
            return ExactRisk(scenario)
        return MonteCarloRisk(scenario, **self._options)

    @property
    def risk_tolerance(self) -> float:
        r"""$\epsilon$ [units of the severity]; ``math.inf`` (with a budget only): no per-step bound."""
        return self._requested_epsilon

    @risk_tolerance.setter
    def risk_tolerance(self, value: float) -> None:
        budget = getattr(self, "risk_budget", None)
        unbounded = checks.is_real(value) and float(value) == math.inf
        if budget is not None and unbounded:
            self._requested_epsilon = math.inf
        else:
            if unbounded:
                raise ValueError(
                    "risk_tolerance=inf (no per-step bound) needs a risk_budget; got risk_budget=None"
                )
            PathFollowingMPC.risk_tolerance.fset(self, value)  # checks, sets _epsilon
            self._requested_epsilon = self._epsilon
        scale = self.estimator.severity.scale
        self._epsilon = rb.effective_tolerance(self._requested_epsilon, budget, self._budget_backoff, scale)

    def spent_risk(self, index: int = 0) -> float:
        r"""$\mathrm{spent}_k$ of batch entry ``index``: the summed one-step risk $R_{1|j}$ of the
        actions applied so far in its episode, by the agent's own estimator (0 without a budget)."""
        return self._spent.get(index, 0.0)

    def refund(self, risk: float, index: int = 0) -> None:
        """Take back ``risk`` (>= 0, the severity's unit) of batch entry ``index``'s spent risk: what
        its last step charged for an object that is no road user (a virtual stop line,
        :mod:`risk_env.highway.gate`). ``ValueError`` for a refund above what was spent."""
        risk = checks.real("risk", risk)
        spent = self._spent.get(index, 0.0)
        if not 0.0 <= risk <= spent * (1.0 + 1e-9) + 1e-15:
            raise ValueError(f"risk must be in [0, spent = {spent:g}], got {risk!r}")
        self._spent[index] = max(spent - risk, 0.0)

    @property
    def samples(self) -> int | None:
        """J, the Monte Carlo draws per step (None for the exact risk)."""
        return getattr(self.estimator, "samples", None)

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self._spent.clear()
        if getattr(self, "_pilot", None) is not None:  # its draws restart too
            self._pilot.reset(None if seed is None else seed + 1)

    def _estimator_key(self) -> tuple[Any, ...]:
        if self.risk_method == "exact":
            return ("exact",)
        est = self.estimator
        return ("monte_carlo", est.samples, est.bandwidth, est.smoothing, est.severity_smoothing)

    def _risk_terms(self) -> tuple[bool, bool]:
        return (self.risk_budget is not None and self.budget_allocation == "horizon", bool(self.risk_weight))

    def _step_epsilon(self, index: int, new_episode: bool) -> float:
        r"""With ``budget_allocation="share"``: $\min(\epsilon, \alpha (B - \mathrm{spent}_k))$, the
        step's share of what is left of the budget (:mod:`agents.mpc.nlp.risk_budget`); else $\epsilon$."""
        if self.risk_budget is None:
            return self._epsilon
        if new_episode:
            self._spent[index] = 0.0
        if self.budget_allocation != "share":
            return self._epsilon
        return rb.share_tolerance(
            self._epsilon, self.risk_budget, self._spent.get(index, 0.0), self.budget_share
        )

    def _step_forms(self) -> set[str]:
        r"""The tolerance's form; with a budget shared out step by step also $\epsilon_k = 0$'s
        (what is left of the budget may run out, after a fallback)."""
        shared = self.risk_budget is not None and self.budget_allocation == "share"
        return {self._risk_variant(), *([self._risk_variant(0.0)] if shared else [])}

    def prepare(self) -> float:
        """:meth:`PathFollowingMPC.prepare`, the Monte Carlo pilot's problems too."""
        pilot = getattr(self, "_pilot", None)
        return super().prepare() + (pilot.prepare() if pilot is not None else 0.0)

    def _risk_value(self, ego: ca.SX, beliefs: list[Belief], data: ca.SX, numbers: ca.SX) -> ca.SX:
        """The per-stage R of the budget and the weight: the constraint's own R (exact:
        :meth:`~risk_env.risk.estimators.ExactRisk.solver_risk`; Monte Carlo: the smoothed estimate) summed
        over the active slots, the expected total harm of the step (linearity of expectation)."""
        J = self.samples or 0
        total = None
        for k, belief in enumerate(beliefs):
            est = symbolic(self.estimators[k], numbers[k, 1], numbers[k, 2])
            if self.risk_method == "monte_carlo":
                r = est.casadi_risk(ego, belief, samples=slot_rows(data, k, J))
            else:
                r = est.solver_risk(ego, belief)
            share = numbers[k, 0] if numbers.shape[1] <= NUMBER_COLUMNS else numbers[k, 0] * numbers[k, 3]
            total = share * r if total is None else total + share * r
        return total

    def _terms_parameters(self, index: int, new_episode: bool) -> np.ndarray:
        if not any(self._risk_terms()):
            return np.zeros(0)
        if new_episode:
            self._spent[index] = 0.0
        scale = self.estimator.severity.scale
        spent = self._spent.get(index, 0.0)
        return rb.terms_parameters(self.risk_budget, spent, self.risk_weight, scale, self._budget_backoff)

    def _step(self, index: int, obs_vec: np.ndarray) -> SolveReport:
        """One step; with a budget, the applied action's one-step risk $R_{1|k}$ is added to spent."""
        report = super()._step(index, obs_vec)
        if self.risk_budget is not None:
            self._spent[index] = self._spent.get(index, 0.0) + float(np.asarray(report.risk_fn())[0])
        return report

    def _risk_parameter_shape(self) -> tuple[int, int]:
        return (self.estimator.samples, 3) if self.risk_method == "monte_carlo" else (0, 0)

    def _margin(
        self, ego: ca.SX, beliefs: list[Belief], epsilon: ca.SX, data: ca.SX, numbers: ca.SX, zero: bool
    ) -> ca.SX:
        J = self.samples or 0
        clearances, risks = [], []
        for k, belief in enumerate(beliefs):
            active, radius = numbers[k, 0], numbers[k, 1]
            est = symbolic(self.estimators[k], radius, numbers[k, 2])
            lift = INACTIVE * (1.0 - active)
            if self.risk_method == "monte_carlo":
                draws = slot_rows(data, k, J)
                if zero:
                    # soft minimum of the distances to the draws: smooth, and below the minimum by
                    # at most CLEARANCE_SOFTNESS * log(J), so clearance >= 0 keeps the disc off
                    # every draw
                    bodies = isinstance(est, BodyRisk)
                    dist = est.distances(ego, draws, belief.theta) if bodies else est.distances(ego, draws)
                    t = CLEARANCE_SOFTNESS
                    nearest = ca.mmin(
                        dist
                    )  # shift for a safe exponent; value and gradient do not depend on it
                    soft = nearest - t * ca.log(ca.sum1(ca.exp(-(dist - nearest) / t)))
                    clearances.append(soft - radius + lift)
                else:
                    risks.append(weighted(active, numbers, k) * est.casadi_risk(ego, belief, samples=draws))
                continue
            box = symbolic(self._worsts[k], radius, numbers[k, 2])
            clearances.append(box.distance(ego, belief, CASADI) - radius + lift)
            if not zero:
                risks.append(weighted(active, numbers, k) * est.solver_risk(ego, belief))
        if zero:  # R <= 0 <=> every disc misses every possible object position (box / draws)
            return ca.vertcat(*clearances)
        total = risks[0]
        for r in risks[1:]:
            total = total + r
        margin = (epsilon - total) / self.estimator.severity.scale
        if self.risk_method == "monte_carlo":
            # (epsilon - R) / scale alone: with epsilon > 0 the smoothed R <= epsilon has an
            # interior and a gradient wherever a draw is near the disc edge, and the clearance's
            # alternative (disc off every draw) could only matter were epsilon below the few
            # joules of the logistic's tails, so it is left out (it doubled an evaluation's cost)
            return margin
        # R <= epsilon <=> every clearance >= 0 or margin >= 0
        nearest = clearances[0]
        for c in clearances[1:]:
            nearest = ca.fmin(nearest, c)
        return ca.fmax(nearest, margin)

    def _pilot_plan(
        self, index: int, obs_vec: np.ndarray, variant: str, epsilon: float = 0.0
    ) -> tuple[np.ndarray, int, tuple[CallRecord, ...]] | None:
        r"""Monte Carlo, cold starts of the ``"general"`` variant: the plan of the same SMPC with
        ``pilot_samples`` draws, itself solved cold from every rollout (its evaluations cost a
        fifth). At $\epsilon = 0$ (``"zero"``) a plan that misses 100 draws may run into the other
        400 (a solve from it took longer than the rollouts), so that variant starts from them."""
        if self._pilot is None or variant != "general":
            return None
        # no per-step risk exceeds the severity's largest, so the bound loses nothing there
        self._pilot.risk_tolerance = min(epsilon, self.estimator.severity.upper_bound)
        self._pilot._memory.pop(index, None)  # a cold start: every rollout, keep the best
        report = self._pilot._step(index, obs_vec)
        self._pilot.last_solve = report
        if report.fallback is not None:
            return None
        return np.column_stack([report.inputs, report.path_speed]), report.iterations, report.calls

    def _risk_data(self, futures: list[Belief | None]) -> np.ndarray:
        if self.risk_method != "monte_carlo":
            return super()._risk_data(futures)
        J, N = self.estimator.samples, self.horizon
        blocks = []
        for f in futures:  # slot by slot: one slot draws exactly as the single-object SMPC did
            if f is None:
                blocks.append(np.zeros((N, J, 3)))
            else:
                blocks.append(np.moveaxis(f.sample(self.rng, J), 0, 1))  # (J, N, 3) -> (N, J, 3)
        return np.ascontiguousarray(np.concatenate(blocks, axis=1))  # (N, K J, 3)

    def _slot_risk(self, slot: int, ego: np.ndarray, belief: Belief, data: np.ndarray) -> np.ndarray:
        if self.risk_method == "monte_carlo":
            return self.estimators[slot].risk(ego, belief, draws=np.moveaxis(data, 1, 0))
        return self.estimators[slot].risk(ego, belief)


def weighted(active: ca.SX, numbers: ca.SX, row: int) -> ca.SX:
    r"""A row's factor on its risk in the expectation: its active flag, times its mode's weight
    $w$ with given beliefs (a fourth column of ``numbers``); the mixture's risk is then
    $\sum_m w_m R_m$, exact by linearity of expectation."""
    return active if numbers.shape[1] <= NUMBER_COLUMNS else active * numbers[row, 3]
