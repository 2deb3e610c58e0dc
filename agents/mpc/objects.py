r"""The MPC's object slots: each slot's estimators (numeric and symbolic), the slots' risk rows
and the numbers a step hands the solver.

An agent has $K$ object slots, fixed at construction (``object_slots``; by default the scenario's
number of objects). Slot $k$ takes object $k$'s radius, mass and uncertainty; slots beyond the
scenario's objects take the last object's (:func:`agents.mpc.nlp.parameters.slot_numbers`). In the
solver these
numbers are parameters, so one built solver serves every scene with up to $K$ objects.

- :func:`symbolic` makes an estimator whose collision distance and object mass are CasADi
  symbols (the solver's parameters), every other number its own.
- :func:`combine` adds the slots' numeric risks of the present objects: $R = \sum_k R_k$, the
  expected total harm (:mod:`risk_env.risk.total_risk`).
"""

from __future__ import annotations

import copy
from typing import Any

import casadi as ca
import numpy as np

from agents.mpc.nlp.parameters import given_vector, slot_numbers
from risk_env.prediction.belief import Belief
from risk_env.risk.bodies import BodyRisk
from risk_env.risk.estimators import RiskEstimator
from risk_env.risk.severity import InjurySeverity, PaperSeverity, PlasticSeverity
from risk_env.scenario.scenario import Scenario


def slot_scenario(scenario: Scenario, slot: int) -> Scenario:
    """The single-object scenario of slot ``slot``: the scenario itself with one object, else
    ``scenario.for_object(k)`` with k = min(slot, objects - 1)."""
    if len(scenario.objects) == 1:
        return scenario
    return scenario.for_object(min(slot, len(scenario.objects) - 1))


def symbolic(estimator: RiskEstimator, radius: ca.SX, mass: ca.SX) -> RiskEstimator:
    """A copy of ``estimator`` with collision distance ``radius`` [m] and object mass ``mass``
    [kg] (symbols; the severity's scale stays the estimator's, a number); bodies of several discs
    keep their discs."""
    if isinstance(estimator, BodyRisk):
        return estimator.rebuilt(symbolic(estimator.inner, radius, mass))
    out = copy.copy(estimator)
    out.radius = radius
    sev, sc = estimator.severity, estimator.scenario
    m_e = sc.ego.mass
    if isinstance(sev, PaperSeverity):
        out.severity = PaperSeverity(m_e, mass)
    elif isinstance(sev, PlasticSeverity):
        out.severity = PlasticSeverity(m_e, mass)
    elif isinstance(sev, InjurySeverity):
        out.severity = InjurySeverity(m_e, mass, sev.beta0, sev.beta1)
    return out


def slot_rows(data: ca.SX, slot: int, rows: int) -> ca.SX:
    """Slot ``slot``'s block ``(rows, 3)`` of one stage's risk data ``(K rows, 3)``."""
    return data[slot * rows : (slot + 1) * rows, :]


def combine(terms: list[np.ndarray]) -> np.ndarray:
    r"""$R = \sum$ over the present slots' risks ``(N,)`` (left to right: one term is itself); zeros
    when none is present."""
    if not terms:
        return np.zeros(0)
    out = np.asarray(terms[0], float).copy()
    for t in terms[1:]:
        out = out + np.asarray(t, float)
    return out


def check_slots(value: Any, scenario: Scenario) -> int:
    r"""``object_slots`` checked: an integer $\ge 1$ (None: the scenario's number of objects)."""
    if value is None:
        return len(scenario.objects)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"object_slots must be an integer >= 1 (or None), got {value!r}")
    return int(value)


class Slots:
    r"""The planning slots: K object slots (the observation's), each with M mode slots, so the
    NLP has K M rows of beliefs; slot (k, m) is row ``k M + m``.

    Without a predictor (the paper's prediction) M = 1 and each row's beliefs are the
    constant-input prediction from the slot's measurement, made inside the NLP. With a
    ``predictor`` (:class:`~risk_env.prediction.predictors.Predictor`) every row's beliefs at
    $n = 1, \dots, N$ and its weight w are solver parameters ("given"): object k's modes, likeliest first,
    fill its M rows (a mixture of more than M modes raises ``ValueError``), absent ones weigh 0.
    """

    def __init__(
        self, scenario: Scenario, objects: int, predictor: Any = None, modes: int | None = None
    ) -> None:
        self.scenario = scenario
        self.objects = objects
        """K, the object slots."""
        self.predictor = predictor
        """The predictor of the given beliefs, or None (the paper's prediction, in the NLP)."""
        default = 1 if predictor is None else int(getattr(predictor, "max_modes", MODES))
        self.modes = default if modes is None else _count("modes", modes)
        """M, the mode slots per object (1 without a predictor)."""
        if predictor is None and self.modes != 1:
            raise ValueError(f"modes={modes} needs a predictor with modes; the paper's prediction has one")
        self.numbers = np.repeat(slot_numbers(scenario, objects), self.modes, axis=0)
        """Each row's numbers ``(K M, 15)``: collision distance [m], mass [kg], uncertainty (13)."""

    @property
    def given(self) -> bool:
        """Whether the rows' beliefs are solver parameters (a predictor is set)."""
        return self.predictor is not None

    @property
    def rows(self) -> int:
        """K M, the rows of beliefs the NLP plans against."""
        return self.objects * self.modes

    def scenario_of(self, row: int) -> Scenario:
        """The single-object scenario of ``row``'s object (:func:`slot_scenario`)."""
        return slot_scenario(self.scenario, row // self.modes)

    def beliefs(self, problem: Any, o: Any) -> tuple[list[Belief | None], np.ndarray, np.ndarray]:
        r"""Each row's beliefs at $n = 1, \dots, N$ (None where absent), its weight ``(K M,)`` and its
        hypothesis's weight ``(K M,)`` (weight / share, :attr:`Mode.share
        <risk_env.prediction.mixture.Mode.share>`: what a mode threshold compares), for the split
        observation ``o``: by the built ``problem``'s own prediction, or the predictor's."""
        if not self.given:
            futures = [
                Belief.from_array(np.asarray(problem.beliefs(o.objects[k], self.numbers[k, 2:]))[1:])
                if here
                else None
                for k, here in enumerate(o.present)
            ]
            weights = np.array([1.0 if f is not None else 0.0 for f in futures])
            return futures, weights, weights
        futures: list[Belief | None] = [None] * self.rows
        weights = np.zeros(self.rows)
        hypotheses = np.zeros(self.rows)
        present = np.flatnonzero(o.present)
        if not len(present):
            return futures, weights, hypotheses
        steps = self.scenario.horizon
        mixtures = self.predictor.predict_scene(o.objects[present], steps)
        for k, mixture in zip(present.tolist(), mixtures, strict=True):
            if len(mixture) > self.modes:
                raise ValueError(
                    f"the predictor gave object slot {k} {len(mixture)} modes; the agent plans against"
                    f" at most modes={self.modes}: build it with modes >= {len(mixture)}"
                )
            if mixture.steps != steps:
                raise ValueError(f"the predictor gave N = {mixture.steps} steps, the horizon is N = {steps}")
            ranked = sorted(mixture.modes, key=lambda mode: -mode.weight)
            for m, mode in enumerate(ranked):
                row = k * self.modes + m
                futures[row] = Belief.from_array(mode.beliefs.as_array()[1:])
                weights[row] = mode.weight
                hypotheses[row] = mode.weight / mode.share
        return futures, weights, hypotheses

    def packing(self, active: np.ndarray, data: bool) -> tuple[int | None, np.ndarray]:
        """``(rows of the NLP, which rows fill them)``: with given beliefs (and no risk data) the
        active rows, packed into the smallest of :data:`CAPACITIES` that holds them, so that rows
        that cannot matter cost nothing (the rest of the NLP's rows absent: the first row's
        numbers, inactive); else every row (None: the full NLP)."""
        if not self.given or data:
            return None, np.arange(self.rows)
        index = np.flatnonzero(active)
        rows = next((c for c in CAPACITIES if c >= max(len(index), 1)), self.rows)
        rows = min(rows, self.rows)
        filler = np.setdiff1d(np.arange(self.rows), index)[: rows - len(index)]
        return rows, np.concatenate([index, filler]).astype(int)

    def capacities(self, data: bool) -> tuple[int | None, ...]:
        """Every row count :meth:`packing` can give a step (``data``: the agent has risk data):
        :data:`CAPACITIES` up to K M, and K M itself; ``(None,)`` (the full NLP) where it does not
        pack."""
        if not self.given or data:
            return (None,)
        rows = {min(c, self.rows) for c in CAPACITIES} | {self.rows}
        return tuple(sorted(rows))

    def given_block(self, futures: list[Belief | None], weights: np.ndarray) -> np.ndarray:
        """The given beliefs' parameters (:func:`agents.mpc.nlp.parameters.given_vector`); empty
        without a predictor."""
        if not self.given:
            return np.zeros(0)
        N = self.scenario.horizon
        fields = np.zeros((len(futures), N, Belief.SIZE))
        fields[..., 4:9] = 1.0  # absent rows: unit spreads (no division by 0), weight 0
        for row, f in enumerate(futures):
            if f is not None:
                fields[row] = f.as_array()
        return given_vector(weights, fields)


CAPACITIES: tuple[int, ...] = (1, 2, 4, 8, 16, 32)
"""The NLPs built for given beliefs, by rows (each lazily): a step runs the smallest that holds its
active rows."""
MODES = 3
"""Mode slots per object with a predictor, by default: straight, left and right at a junction."""


def _count(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


MODE_THRESHOLD = 0.05
"""$w_{min}$ by default: the RMPC plans against every mode whose weight is at least this."""


def check_threshold(value: Any) -> float:
    """``mode_threshold`` checked: a number in [0, 1]."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"mode_threshold must be a number in [0, 1], got {value!r}")
    if not 0.0 <= float(value) <= 1.0:
        raise ValueError(f"mode_threshold must lie in [0, 1], got {value!r}")
    return float(value)
