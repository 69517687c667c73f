"""How far a peer's strikes are from ours: per quantity and strike, and the one number the
tuning minimises."""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

from .strike import Outcome, Strike, StrikeKind


class Quantity(enum.Enum):
    COR = 'cor'  # kinematic coefficient of restitution [-]
    DURATION = 'duration'  # contact duration [s]
    F_MAX = 'F_max'  # peak normal force [N]
    V_T_AFTER = 'v_t_after'  # tangential tip velocity after the contact [m/s]


# the coefficient of restitution is what a user of the peer sees first (the rebound);
# duration, peak force and the tangential rebound follow it in weight
WEIGHTS = {Quantity.COR: 4.0, Quantity.DURATION: 1.0, Quantity.F_MAX: 1.0, Quantity.V_T_AFTER: 1.0}


def value(outcome: Outcome, quantity: Quantity) -> float:
    return float(getattr(outcome, quantity.value))


def _scale(ours: Outcome, quantity: Quantity, strike: Strike) -> float:
    """What an error is relative to: our value; the strike's speed for the tangential
    velocity (it passes through zero across the range)."""
    return strike.speed if quantity is Quantity.V_T_AFTER else abs(value(ours, quantity))


def error(ours: Outcome, peer: Outcome, quantity: Quantity, strike: Strike) -> float:
    """The peer's error (its phase mean's), relative as ``_scale`` says."""
    return (value(peer, quantity) - value(ours, quantity)) / _scale(ours, quantity, strike)


def spread(ours: Outcome, peer: Outcome, quantity: Quantity, strike: Strike) -> float | None:
    """The range (max - min) of the peer's quantity over the phases of its time step,
    relative as the error is; None when the peer ran one phase (no spread measured)."""
    if not peer.phases:
        return None
    values = [value(p, quantity) for p in peer.phases]
    return (max(values) - min(values)) / _scale(ours, quantity, strike)


# the arm lives at its limit-cycle impact (the oblique strike at 1x): it counts this many
# times each other strike, so that the exported peer rebounds there as ours does
CYCLE_IMPACT_WEIGHT = 25.0


def strike_weight(strike: Strike) -> float:
    cycle = strike.kind is StrikeKind.OBLIQUE and strike.speed_ratio == 1.0
    return CYCLE_IMPACT_WEIGHT if cycle else 1.0


def cost(ours: Sequence[Outcome], peer: Sequence[Outcome], strikes: Sequence[Strike]) -> float:
    """Weighted mean of the squared relative errors; inf when a peer's tip did not leave
    the surface (no rebound to compare)."""
    total = weights = 0.0
    for o, p, s in zip(ours, peer, strikes):
        if not p.separated:
            return math.inf
        for quantity, weight in WEIGHTS.items():
            e = error(o, p, quantity, s)
            if not math.isfinite(e):
                return math.inf
            total += strike_weight(s) * weight * e * e
            weights += strike_weight(s) * weight
    return total / weights


@dataclass(frozen=True)
class Worst:
    quantity: Quantity
    rms: float  # root mean square relative error (of the phase means) over the strikes
    worst: float  # largest absolute relative error
    at: str  # the strike where it is largest
    # the largest range over the phases of the step at one strike, relative (None: one
    # phase run): the peer's own scatter in a closed loop, which no parameter removes
    spread: float | None = None
    spread_at: str = ''


def summary(
    ours: Sequence[Outcome], peer: Sequence[Outcome], strikes: Sequence[Strike]
) -> list[Worst]:
    out = []
    for quantity in Quantity:
        errors = [error(o, p, quantity, s) for o, p, s in zip(ours, peer, strikes)]
        k = max(range(len(errors)), key=lambda i: abs(errors[i]))
        rms = math.sqrt(sum(e * e for e in errors) / len(errors))
        spreads = [spread(o, p, quantity, s) for o, p, s in zip(ours, peer, strikes)]
        measured = [(x, s.label) for x, s in zip(spreads, strikes) if x is not None]
        # NaN is not smaller than anything: a NaN spread is the largest, never skipped
        widest = max(measured, key=lambda m: math.inf if math.isnan(m[0]) else m[0], default=None)
        out.append(
            Worst(
                quantity,
                rms,
                abs(errors[k]),
                strikes[k].label,
                None if widest is None else widest[0],
                '' if widest is None else widest[1],
            )
        )
    return out
