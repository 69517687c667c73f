"""Contact parameters fitted by running the peer: a bounded Nelder-Mead search over the
peer's parameters (in the space ``PeerProblem`` maps them to) for the least ``residual.cost``
between the peer's strikes and ours."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

from .residual import cost
from .strike import Outcome, Strike

Contact = TypeVar('Contact')


@dataclass(frozen=True)
class Parameter:
    name: str
    start: float  # in the search's space
    low: float
    high: float
    log: bool = False  # searched as log10 of the value


@dataclass(frozen=True)
class PeerProblem(Generic[Contact]):
    """What the search needs of a peer: its parameters, how a point of the search becomes
    the peer's contact, and the peer's outcome of the strikes with it."""

    parameters: tuple[Parameter, ...]
    contact: Callable[[dict[str, float]], Contact]
    outcomes: Callable[[Contact, Sequence[Strike]], list[Outcome]]


@dataclass(frozen=True)
class Tuned(Generic[Contact]):
    contact: Contact
    outcomes: list[Outcome]
    cost: float
    evaluations: int


def values(parameters: Sequence[Parameter], x: Sequence[float] | np.ndarray) -> dict[str, float]:
    return {p.name: float(10.0**v if p.log else v) for p, v in zip(parameters, x)}


def tune(
    problem: PeerProblem[Contact], strikes: Sequence[Strike], ours: Sequence[Outcome], budget: int
) -> Tuned[Contact]:
    """The peer's contact of least cost found within ``budget`` peer evaluations."""
    from scipy.optimize import minimize

    if budget < 1:
        raise ValueError(f'tuning budget {budget}: must be at least 1 evaluation')
    params = problem.parameters
    best: dict = {'cost': math.inf, 'x': None}
    count = [0]

    def objective(x: np.ndarray) -> float:
        count[0] += 1
        try:
            contact = problem.contact(values(params, x))
        except ValueError:  # a point outside what the peer accepts
            return math.inf
        c = cost(ours, problem.outcomes(contact, strikes), strikes)
        if c < best['cost']:
            best['cost'], best['x'] = c, np.array(x, float)
        return c

    x0 = np.array([p.start for p in params], float)
    bounds = [(p.low, p.high) for p in params]
    minimize(
        objective,
        x0,
        method='Nelder-Mead',
        bounds=bounds,
        options={'maxfev': budget, 'xatol': 1e-4, 'fatol': 1e-8, 'adaptive': True},
    )
    if best['x'] is None:
        raise ValueError('tuning: no candidate gave the peer a rebound on every strike')
    contact = problem.contact(values(params, best['x']))
    return Tuned(contact, problem.outcomes(contact, strikes), best['cost'], count[0])
