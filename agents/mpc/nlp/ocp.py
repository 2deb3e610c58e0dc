r"""The path-following optimal control problem (paper Secs. III-VI), written once as a CasADi NLP.

The sections of :func:`assemble`, in order:

- **Variables** (multiple shooting, stage-wise as fatrop expects): per stage $n = 0, \dots, N$ the
  state $x_n = (c_1, c_2, \theta, \lambda, v_{n-1}, \omega_{n-1})$ and per $n = 0, \dots, N-1$ the
  input $u_n = (v, \omega, u_2)$. The state carries the previous input so that the rate limits and
  the risk's ego speed are stage-local. $x_0$ is fixed by its bounds (lbx = ubx) to the measurement:
  the ego pose (heading unwrapped near $\theta_P(\lambda_k)$), the last applied input and
  $\lambda_k$, the observation's closest-point progress.
- **Dynamics**: the ego unicycle (:func:`risk_env.models.dynamics.casadi_step`) and the timing law
  $\lambda_{n+1} = \lambda_n + u_2 \cos(\theta_n - \theta_P(\lambda_n))\, T$
  (:func:`risk_env.models.path.timing_law`).
- **Objective**: $\sum e^T W e$,
  $e = (c_1 - c_{1,P}(\lambda), c_2 - c_{2,P}(\lambda), \theta - \theta_P(\lambda), u_2 - v_{ref})$
  (:func:`risk_env.models.path.path_error` with the unwrapped heading), no terminal cost.
  ``stage_cost="reached"`` (default) sums the pose part over the states $n = 1, \dots, N$ that the
  inputs reach and the speed part over $u_{2,0}, \dots, u_{2,N-1}$. The paper's sum over
  $n = 0, \dots, N-1$ (``stage_cost="paper"``) holds a constant pose term at $n = 0$ and leaves the
  last input $(v, \omega)_{N-1}$ without any cost (it only moves $x_N$, which nothing weighs), so its
  optimum is not unique there.
- **Constraints**: $v \in [v_{min}, v_{max}]$, $|\omega| \le \omega_{max}$; rate limits
  $|v_n - v_{n-1}| \le a_{max} T$, $|\omega_n - \omega_{n-1}| \le \dot\omega_{max} T$ ($a_{max}$ =
  ``accel_max``, $\dot\omega_{max}$ = ``omega_rate_max``) with $(v, \omega)_{-1}$ the last applied
  input; with a finite ``curvature_max`` $\kappa_{max}$, $|\omega_n| \le \kappa_{max} v_n$ (a car turns
  only while it moves; none for the paper's unicycle); $u_2 \in [v_{min}, v_{max}]$ (the paper's
  $u_2 \in \mathcal{V}_e$, the ego's own speed set, so the reference point may wait or step back with
  a reversing ego);
  $\lambda_n \ge \lambda_0$ (the path's start) and no upper cap (the path continues beyond the goal);
  the agent's risk constraint $\mathrm{margin}_n \ge \mathrm{backoff}$ for $n = 1, \dots, N$ at the
  ego's predicted state $n$ with speed $v_{n-1}$ (the input that led there: the env's $R_{k+1|k}$),
  against the object's belief at step $n$, :func:`risk_env.predict` built symbolically on the
  object-measurement parameter.
- **Parameters** (nlpsol ``p``, :func:`parameter_vector`): $\epsilon$, $v_{ref}$, then per object slot
  $k = 0, \dots, K-1$ (:data:`SLOT_SIZE` numbers): its measurement $(c_1, c_2, \theta, v, \omega)$,
  ``active`` (1: the object is present and may reach the ego within the horizon, 0: its rows cost
  nothing), its collision distance $r_e + r_o$ [m], its mass $m_o$ [kg] (for the severity) and the numbers of
  its :class:`~risk_env.scenario.scenario.Uncertainty` (:func:`uncertainty_vector`); then the agent's risk
  data per stage (Monte Carlo draws, every slot's); last, with the episode budget or the risk
  weight, the :data:`TERMS` numbers. Agents that differ only in their tolerance, reference speed,
  uncertainty level, start or objects share one built (or compiled) solver (:func:`problem_key`),
  and a solver with $K$ slots serves every scene with up to $K$ objects without a rebuild.
- **Risk rows of many objects** (:data:`Margin`): the agent's margin returns the rows of one stage
  for all $K$ slots: the RMPC one row per slot ($\mathrm{margin}_k + \mathrm{BIG}\,(1 - a_k)$, $a_k$
  the slot's ``active`` flag: an inactive slot's row holds by :data:`INACTIVE` margin units,
  whatever its numbers), the SMPC one row per stage on the sum of the slots' risks,
  $\sum_k a_k R_k \le \epsilon$. The budget's and the weight's per-stage $R$ (:data:`RiskValue`) is
  that sum too: by linearity of expectation the expected total harm of the step. A solver with one slot
  solves its risk variants only when the slot is active (else ``"free"``), so there the flag is the constant
  1, which CasADi folds away: the rows, their derivatives and the solver's iterates are the single-object
  ones bit for bit (a parameter equal to 1 would be exact in value, but its extra nodes reorder the
  derivatives' sums).
- **Variants** of the same NLP (:data:`VARIANTS`): ``"general"``; ``"zero"`` (the agent's exact
  form at $\epsilon = 0$); ``"free"``, without risk rows, used when no step's risk can be nonzero
  anywhere the ego can reach within the horizon: then the constraints cannot bind and the free
  problem has the same solution, at a fraction of the cost. ``"general_soft"`` and
  ``"zero_soft"``: the risk rows softened, $\mathrm{margin}_n + s_n \ge \mathrm{backoff}$ with
  slacks $s_n \ge 0$ [margin units] and $\sum_n \rho_n s_n$ added to the objective,
  $\rho_n = \rho\, q^{N - n}$ ($\rho$ = ``soft_penalty``, $q$ = :data:`EARLY_WEIGHT`; an exact L1
  penalty: whenever every $\rho_n$ exceeds its risk row's multiplier, every solution of the hard problem
  solves the soft one with $s = 0$, and a soft solution with $s = 0$ solves the hard problem). A slack costs
  up to twice as much near the object's predicted mean (:data:`NEAR_WEIGHT`): where the boxes cannot be kept
  off, the plan misses them where the object is least likely. The slack of row $n$ is a
  control of stage $n$ (the last stage's after $x_N$), so the problem stays stage-wise for fatrop.
  The path's corridor is soft there too (:mod:`agents.mpc.nlp.corridor`).

The solver built on this NLP lives in :mod:`agents.mpc.nlp.solver`; the controller that calls it in
:mod:`agents.mpc.controller`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import casadi as ca

from agents.mpc.nlp.corridor import CORRIDOR_SLACK, corridor_rows, corridor_weight
from agents.mpc.nlp.parameters import (
    NUMBER_COLUMNS,
    SLOT_SIZE,
    TERMS,
    UNCERTAINTY_NUMBERS,
    given_size,
    symbolic_uncertainty,
)
from risk_env.models.dynamics import casadi_step
from risk_env.models.frame import to_frame
from risk_env.models.ops import CASADI
from risk_env.models.path import lateral_offset, path_error, timing_law
from risk_env.prediction.belief import Belief, predict
from risk_env.scenario.scenario import Pose, Scenario

STAGE_COSTS: tuple[str, ...] = ("reached", "paper")
SOFT = "_soft"
"""Suffix of the soft variants."""
VARIANTS: tuple[str, ...] = ("general", "zero", "free", "general" + SOFT, "zero" + SOFT)
EARLY_WEIGHT = 4.0
r"""A soft variant's slack of row $n$ costs $\rho\, q^{N - n}$ ($q$ = ``EARLY_WEIGHT``): the earlier a
violation, the dearer (near lexicographic: the plan keeps clear first at $n = 1$, then at $n = 2$, ...), since
the object's early positions are the likely ones and the later boxes only grow."""
NEAR_WEIGHT = 1.0
r"""A soft variant's slack of row $n$ costs up to ``1 + NEAR_WEIGHT`` times $\rho_n$ where the ego is at
the object's predicted mean (a Gaussian bump of the belief's spread widened by $r_e + r_o$)."""
PARKED = Pose(0.0, 0.0, 0.0)
"""The pose :func:`problem_key` puts in place of the starts, which the NLP does not see."""
NX = 6
r"""Stage state: $c_1$ [m], $c_2$ [m], $\theta$ [rad], $\lambda$ [m], previous $v$ [m/s], previous
$\omega$ [rad/s]."""
NU = 3
r"""Stage input: $v$ [m/s], $\omega$ [rad/s], $u_2$ [m/s]."""

Margin = Callable[[ca.SX, list[Belief], ca.SX, ca.SX, ca.SX, bool], ca.SX]
r"""``(ego (4,), beliefs (one per slot), epsilon, risk data (K J, 3), slot numbers (K, 3): active,
collision distance [m], mass [kg], zero) -> rows``: every row $\ge 0$ iff the step's risk bound holds."""
RiskValue = Callable[[ca.SX, list[Belief], ca.SX, ca.SX], ca.SX]
"""``(ego (4,), beliefs (one per slot), risk data (K J, 3), slot numbers (K, 3)) -> R``: the agent's
per-stage risk summed over the active slots (the budget's and the cost's)."""
Layout = tuple[list[tuple[int, str, int]], list[tuple[int, str, int]], list[float], list[float]]
"""``(w_tags, g_tags, lbg, ubg)``: (stage, kind, component) of every variable and row, row bounds."""


def risk_form(variant: str) -> str:
    """The risk rows' form of a variant: ``"general"``, ``"zero"`` or ``"free"``."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown NLP variant {variant!r}; expected one of {VARIANTS}")
    return variant.removesuffix(SOFT)


def soft_variant(variant: str) -> str:
    """The soft variant of a hard one with risk rows (``"general"`` -> ``"general_soft"``)."""
    form = risk_form(variant)
    if form == "free":
        raise ValueError("the free variant has no risk rows to soften")
    return form + SOFT


def data_shape(risk_shape: tuple[int, int], slots: int) -> tuple[int, int]:
    """Shape of one stage's risk data parameter: every slot's ``risk_shape`` rows stacked."""
    return (risk_shape[0] * slots, risk_shape[1]) if risk_shape[0] else (0, 0)


def stage_functions(
    scenario: Scenario,
    variant: str,
    margin: Margin,
    risk_shape: tuple[int, int],
    value: RiskValue | None = None,
    slots: int = 1,
    given: bool = False,
) -> dict[str, ca.Function | None]:
    r"""The stage functions: ``f`` (x, u) -> $x_{next}$ (the ego model with the timing law),
    ``pose_cost`` x -> the pose part of $e^T W e$, ``risk`` (ego, beliefs (K, Belief.SIZE), $\epsilon$,
    data, slot numbers (K, 3), with ``given`` beliefs (K, 4): the weight $w$ last) -> rows (None for
    ``"free"``) and, with ``value``, ``risk_value`` (ego, beliefs, data, slot numbers) -> $R$ (None for
    ``"free"`` or without ``value``)."""
    sc = scenario
    dt, path, ego = sc.dt, sc.path, sc.ego
    w_c1, w_c2, w_th, _ = sc.cost_weights
    x, u = ca.SX.sym("x", NX), ca.SX.sym("u", NU)
    pose_next = casadi_step(x[0:3], u[0:2], dt)
    lam_next = timing_law(path, x[3], x[2], u[2], dt, CASADI)
    f = ca.Function("f", [x, u], [ca.vertcat(pose_next, lam_next, u[0], u[1])])
    e1, e2, e3, _ = path_error(path, x[0], x[1], x[2], 0.0, x[3], ego.v_ref, CASADI, wrap=False)
    pose_cost = ca.Function("pose_cost", [x], [w_c1 * e1**2 + w_c2 * e2**2 + w_th * e3**2])
    risk = None
    form = risk_form(variant)
    if form != "free":
        ego_s, belief_s = ca.SX.sym("ego", 4), ca.SX.sym("belief", slots * Belief.SIZE)
        eps_s, data_s = ca.SX.sym("epsilon"), ca.SX.sym("data", *data_shape(risk_shape, slots))
        slot_s = ca.SX.sym("slots", slots, NUMBER_COLUMNS + int(given))
        numbers = slot_s if slots > 1 or given else ca.horzcat(ca.DM.ones(1, 1), slot_s[:, 1:])
        size = Belief.SIZE
        beliefs = [Belief.from_array(belief_s[k * size : (k + 1) * size]) for k in range(slots)]
        rows = margin(ego_s, beliefs, eps_s, data_s, numbers, form == "zero")
        # only the ego state is a variable: no derivatives for the rest (compiled code: less)
        risk = ca.Function(
            "risk",
            [ego_s, belief_s, eps_s, data_s, slot_s],
            [rows],
            {"is_diff_in": [True, False, False, False, False]},
        )
    risk_value = None
    if form != "free" and value is not None:
        r = value(ego_s, beliefs, data_s, numbers)
        risk_value = ca.Function(
            "risk_value",
            [ego_s, belief_s, data_s, slot_s],
            [r],
            {"is_diff_in": [True, False, False, False]},
        )
    return {"f": f, "pose_cost": pose_cost, "risk": risk, "risk_value": risk_value}


def assemble(
    sym: type,
    scenario: Scenario,
    stages: dict[str, ca.Function | None],
    risk_shape: tuple[int, int],
    stage_cost: str,
    soft_penalty: float | None = None,
    terms: tuple[bool, bool] = (False, False),
    slots: int = 1,
    given: bool = False,
) -> tuple[dict[str, Any], Layout, ca.Function]:
    r"""The NLP with symbols of type ``sym`` (``ca.SX``: the stage functions inlined; ``ca.MX``:
    called) for ``slots`` object slots, its :data:`Layout` and one object's beliefs' function
    (measurement (5,), uncertainty numbers (13,)) -> ``(N+1, Belief.SIZE)``. ``soft_penalty`` $\rho$:
    soften the risk rows with slacks (one per stage, tagged ``(n, "s", 0)``, shared by the stage's
    rows) at cost $\rho\, s_n$ (a soft variant). ``terms`` = (budget, weight): the :data:`TERMS`
    parameters at the end of p, and (with a ``risk_value`` stage function) the episode budget's
    accumulator and row, the weighted risk in the objective (see the module). ``given``: the slots'
    beliefs at $n = 1, \dots, N$ and their weights are parameters
    (:func:`~agents.mpc.nlp.parameters.given_vector`, at the very end of p: any predictor's modes), not the
    constant-input prediction from each slot's measurement."""
    sc = scenario
    N, ego = sc.horizon, sc.ego
    w_v = sc.cost_weights[3]
    dv, dw = ego.accel_max * sc.dt, ego.omega_rate_max * sc.dt
    f, pose_cost, risk = stages["f"], stages["pose_cost"], stages["risk"]

    # --- parameters (parameter_vector's layout): epsilon; per slot its measurement, active flag,
    # collision distance, mass and uncertainty numbers; per-step risk data; the slots' beliefs
    n_unc = UNCERTAINTY_NUMBERS
    p_eps = sym.sym("epsilon")
    p_vref = sym.sym("v_ref")
    p_slots = [sym.sym(f"slot_{k}", SLOT_SIZE) for k in range(slots)]
    p_data = [sym.sym(f"risk_data_{n}", *data_shape(risk_shape, slots)) for n in range(1, N + 1)]
    with_terms = any(terms)
    p_terms = sym.sym("risk_terms", TERMS) if with_terms else None
    extra = [p_terms] if with_terms else []
    p_given = [sym.sym(f"given_{k}", given_size(N)) for k in range(slots)] if given else []
    p = ca.vertcat(p_eps, p_vref, *p_slots, *(ca.vec(d) for d in p_data), *extra, *p_given)
    slot_numbers = ca.horzcat(*(q[5:8] for q in p_slots)).T  # (K, 3): active, distance, mass
    if given:  # (K, 4): and the weight
        slot_numbers = ca.horzcat(slot_numbers, ca.vertcat(*(q[0] for q in p_given)))
    fields = [f.name for f in dataclasses.fields(Belief)]

    def stack(measurement: Any, numbers: Any) -> list[Any]:
        bs = predict(sc, measurement, steps=N, ops=CASADI, uncertainty=symbolic_uncertainty(numbers))
        return [ca.vertcat(*(getattr(b, k) for k in fields)) for b in bs]

    per_slot = [stack(q[0:5], q[8 : 8 + n_unc]) for q in p_slots]
    if given:  # n = 0 keeps the measured belief (unused by the rows); n >= 1 the given ones
        size = Belief.SIZE
        per_slot = [
            [b[0]] + [q[1 + (n - 1) * size : 1 + n * size] for n in range(1, N + 1)]
            for b, q in zip(per_slot, p_given, strict=True)
        ]
    stacked = [ca.vertcat(*(b[n] for b in per_slot)) for n in range(N + 1)]
    q_obj, q_unc = sym.sym("object", 5), sym.sym("uncertainty", n_unc)
    belief_fn = ca.Function("beliefs", [q_obj, q_unc], [ca.horzcat(*stack(q_obj, q_unc)).T])

    # --- variables, stage by stage: x_0, u_0, x_1, u_1, ..., x_N
    X = [sym.sym(f"x_{n}", NX) for n in range(N + 1)]
    U = [sym.sym(f"u_{n}", NU) for n in range(N)]
    soft = soft_penalty is not None and risk is not None
    S = {n: sym.sym(f"s_{n}") for n in range(1, N + 1)} if soft else {}
    value = stages.get("risk_value")
    budget = terms[0] and value is not None
    weight = p_terms[4] if terms[1] and value is not None else None
    C = {n: sym.sym(f"c_{n}") for n in range(1, N + 1)} if budget else {}  # sum of R_1..R_{n-1}
    s_budget = sym.sym("s_budget") if budget and soft else None
    SC = {n: sym.sym(f"sc_{n}") for n in S} if math.isfinite(sc.path.corridor) else {}  # the corridor's
    w: list[Any] = []
    w_tags: list[tuple[int, str, int]] = []
    g: list[Any] = []
    g_tags: list[tuple[int, str, int]] = []
    lbg: list[float] = []
    ubg: list[float] = []

    def add_g(expr: Any, lo: float, hi: float, stage: int, kind: str) -> None:
        g.append(expr)
        for i in range(expr.numel()):
            g_tags.append((stage, kind, i))
            lbg.append(lo)
            ubg.append(hi)

    def ego_at(n: int) -> Any:
        return ca.vertcat(X[n][0], X[n][1], X[n][2], X[n][4])  # pose of state n, speed v_{n-1}

    values = {}
    if C or weight is not None:
        values = {n: value(ego_at(n), stacked[n], p_data[n - 1], slot_numbers) for n in range(1, N + 1)}

    def near_weight(x: Any, b: Any) -> Any:
        r"""A slack costs more where an object is likelier: 1 + NEAR_WEIGHT times the largest, over
        the active slots, of a Gaussian bump at the slot's predicted mean (its belief's spread,
        in its frame, widened by its $r_e + r_o$); $\ge 1$, so the penalty stays exact."""
        bumps = []
        for k in range(slots):
            q = b[k * Belief.SIZE : (k + 1) * Belief.SIZE]
            r2 = slot_numbers[k, 1] ** 2
            along, across = to_frame(x[0] - q[0], x[1] - q[1], q[11], CASADI)
            z2 = along**2 / (q[4] ** 2 + r2) + across**2 / (q[5] ** 2 + r2)
            bumps.append(ca.exp(-0.5 * z2) if slots == 1 else slot_numbers[k, 0] * ca.exp(-0.5 * z2))
        bump = bumps[0]
        for other in bumps[1:]:
            bump = ca.fmax(bump, other)
        return 1.0 + NEAR_WEIGHT * bump

    def add_risk(n: int) -> Any:
        """The risk row of state $n$ (its slack added in a soft variant), at $n = N$ the budget row;
        their cost terms."""
        if risk is None:
            return 0.0
        row = risk(ego_at(n), stacked[n], p_eps, p_data[n - 1], slot_numbers)
        cost = 0.0 if weight is None else weight * values[n]
        if soft:
            row = row + S[n]
            cost += soft_penalty * EARLY_WEIGHT ** (N - n) * near_weight(X[n], stacked[n]) * S[n]
        add_g(row, 0.0, math.inf, n, "risk")
        if C and n == N:  # (B' - spent - R_N) * normaliser - c_N + switch-off >= backoff
            left = (p_terms[0] - p_terms[1] - values[N]) * p_terms[2] - C[N] + p_terms[3]
            add_g(left + s_budget if soft else left, 0.0, math.inf, N, "budget")
            cost += soft_penalty * s_budget if soft else 0.0
        return cost

    def add_slack(n: int) -> None:
        """The slack of row $n$, a control of stage $n$ (after $u_n$; after $x_N$ for $n = N$; the budget
        row's after that)."""
        if n in S:
            w.append(S[n])
            w_tags.append((n, "s", 0))
        if n == N and s_budget is not None:
            w.append(s_budget)
            w_tags.append((N, "s", 1))
        if n in SC:
            w.append(SC[n])
            w_tags.append((n, "s", CORRIDOR_SLACK))

    def add_corridor(n: int) -> Any:
        """|lateral offset of state n from the arc| <= the path's corridor (none when infinite;
        soft in a soft variant: :mod:`agents.mpc.nlp.corridor`); its slack's cost."""
        if math.isfinite(sc.path.corridor):
            offset = lateral_offset(sc.path, X[n][0], X[n][1], CASADI)
            _ = [
                add_g(r, lo, hi, n, "corridor")
                for r, lo, hi in corridor_rows(offset, sc.path.corridor, SC.get(n))
            ]
        return soft_penalty * corridor_weight(N, EARLY_WEIGHT) * SC[n] if n in SC else 0.0

    def add_accumulator(n: int) -> None:
        r"""$c_{n+1} = c_n + \nu R_n$ ($c_1 = 0$, $\nu$ the normaliser), the gap row's last component:
        stage-local."""
        if C and n < N:
            add_g(C[n + 1] - (C[n] + p_terms[2] * values[n] if n >= 1 else 0.0), 0.0, 0.0, n, "accumulate")

    # --- objective, dynamics, rate limits and risk, stage-wise
    cost = 0.0
    for n in range(N):
        w += [X[n], *([C[n]] if n in C else []), U[n]]
        w_tags += [(n, "x", i) for i in range(NX)] + ([(n, "c", 0)] if n in C else [])
        w_tags += [(n, "u", i) for i in range(NU)]
        add_slack(n)
        add_g(X[n + 1] - f(X[n], U[n]), 0.0, 0.0, n, "gap")
        add_accumulator(n)
        add_g(U[n][0] - X[n][4], -dv, dv, n, "rate_v")
        add_g(U[n][1] - X[n][5], -dw, dw, n, "rate_omega")
        if math.isfinite(ego.curvature_max):  # |omega| <= kappa v: it turns only while it moves
            kappa_v = ego.curvature_max * U[n][0]
            add_g(ca.vertcat(kappa_v - U[n][1], kappa_v + U[n][1]), 0.0, math.inf, n, "curvature")
        if n >= 1:
            cost += add_risk(n) + add_corridor(n)
        cost += w_v * (U[n][2] - p_vref) ** 2
        cost += pose_cost(X[n + 1] if stage_cost == "reached" else X[n])
    w += [X[N], *([C[N]] if C else [])]
    w_tags += [(N, "x", i) for i in range(NX)] + ([(N, "c", 0)] if C else [])
    add_slack(N)
    cost += add_risk(N) + add_corridor(N)
    nlp = {"x": ca.vertcat(*w), "f": cost, "g": ca.vertcat(*g), "p": p}
    return nlp, (w_tags, g_tags, lbg, ubg), belief_fn


def problem_key(scenario: Scenario) -> tuple[Any, ...]:
    r"""What of the scenario is built into a solver: all but the parameters ($\epsilon$, $v_{ref}$, the
    uncertainty, every object's numbers: each slot's are parameters) and what the NLP never sees
    (the ego's start and initial input, measured at each step; the episode's step limit), but
    with the objects' discs (their offsets shape the rows). The
    slot count is the agent's, keyed beside this."""
    rest = max(scenario.ego.v_min, 0.0)  # a valid v_ref and input for every ego
    ego = dataclasses.replace(scenario.ego, start=PARKED, v_ref=rest, initial_input=(rest, 0.0))
    skip = ("risk_tolerance", "uncertainty", "max_steps", "ego", "objects")
    fields = dataclasses.fields(scenario)
    kept = tuple((f.name, getattr(scenario, f.name)) for f in fields if f.name not in skip)
    bodies = tuple(o.disc_offsets for o in scenario.objects)  # the rows' pairs of discs: built in
    return (("ego", ego), ("bodies", bodies), *kept)
