"""The period loop shared by every sampled run (the simulated driver's periods, offline held
control) and the event-path runs: advance the integrator, feed its located events to the impact
builder, collect the impacts completed and the period's contact impulse."""

from __future__ import annotations

from collections.abc import Callable, Iterable

from .impact import Impact
from .integrator import PhaseIntegrator
from .metrics import ImpactBuilder


def feed_events(
    integ: PhaseIntegrator,
    builder: ImpactBuilder,
    events: Iterable,
    on_event: Callable | None = None,
) -> list[tuple[Impact, list]]:
    """Feed located ``events`` to the impact ``builder`` (``on_event`` sees each first).
    Returns the impacts completed [(record, trace rows)], each taking the trace so far."""
    impacts: list[tuple[Impact, list]] = []
    for event in events:
        if on_event is not None:
            on_event(event)
        record = builder.feed(event)
        if record is not None:
            rows = []
            if integ.trace is not None:
                rows, integ.trace[:] = integ.trace[:], []
            impacts.append((record, rows))
    return impacts


def advance_period(
    integ: PhaseIntegrator, builder: ImpactBuilder, t_end: float, on_event: Callable | None = None
) -> tuple[list[tuple[Impact, list]], tuple[float, float]]:
    """The one period loop of every sampled run (the driver's periods, offline held control):
    advance ``integ`` to ``t_end`` and ``feed_events``. Returns the impacts completed and the
    contact impulse (tangential, normal) over the period, which callers divide by the period
    for the averaged wrench."""
    impacts = feed_events(integ, builder, integ.advance(t_end), on_event)
    return impacts, integ.take_impulse()
