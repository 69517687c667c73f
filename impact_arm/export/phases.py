"""A peer's strike run at several phases of its time step, and their mean.

A discrete peer's rebound depends on where inside a time step the contact begins (MuJoCo's
exported paper contact: e 0.376 to 0.404, linear over one step). A strike started exactly
at contact meets one phase; a closed loop meets every phase. Each strike is therefore run
from ``PHASES`` starts, moved back along the joint rates by a fraction of a step, so that
the contact begins at that fraction inside the first step; the tuning scores the mean of
the phases, and the report shows their spread, which no contact parameter removes."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from .strike import Outcome, Strike

# four starts, at the midpoints of four equal parts of a step: their mean is the mean over
# a uniform phase of any quantity linear in the phase (MuJoCo's e is, measured)
PHASES = 4


def offsets(count: int = PHASES) -> tuple[float, ...]:
    """The fractions of a step at which the contact begins, one per phase."""
    if count < 1:
        raise ValueError(f'phases {count}: must be at least 1')
    return tuple((k + 0.5) / count for k in range(count))


def shifted(strike: Strike, fraction: float, timestep: float) -> Strike:
    """The strike started ``fraction`` of a step before its contact: joint angles moved back
    along the joint rates (a step's gravity changes the speed by 5e-5 m/s at 5 µs: left)."""
    lead = fraction * timestep
    return dataclasses.replace(
        strike,
        q=tuple(float(x) for x in np.asarray(strike.q) - np.asarray(strike.qd) * lead),
        joints=tuple(
            float(x) for x in np.asarray(strike.joints) - np.asarray(strike.joint_rates) * lead
        ),
    )


def mean(outcomes: Sequence[Outcome]) -> Outcome:
    """The mean outcome of the phases, which it keeps (``Outcome.phases``); separated only
    when every phase separated. A NaN in any phase makes the mean NaN."""
    if not outcomes:
        raise ValueError('phase mean of no outcome')

    def avg(name: str) -> float:
        return math.fsum(float(getattr(o, name)) for o in outcomes) / len(outcomes)

    return Outcome(
        avg('cor'),
        avg('duration'),
        avg('F_max'),
        avg('v_t_after'),
        all(o.separated for o in outcomes),
        tuple(outcomes),
    )


def over_phases(
    run: Callable[[Strike], Outcome], strike: Strike, timestep: float, count: int = PHASES
) -> Outcome:
    """``run`` of the strike at each phase of ``offsets(count)``, and their mean; the phases
    stop at the first whose tip does not leave the surface (the mean is then unseparated,
    which the tuning scores as no rebound: a stuck strike runs the peer's longest)."""
    out = []
    for fraction in offsets(count):
        out.append(run(shifted(strike, fraction, timestep)))
        if not out[-1].separated:
            break
    return mean(out)
