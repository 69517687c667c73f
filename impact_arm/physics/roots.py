"""Locating an event's zero crossing inside a step, for both compiled integrators.

The arm's kernel (``kernel/events.py``) and the free body's (``bodies/kernel.py``) locate a
switch with ``locate_crossing``: it steps from the start of the step that crossed the event
to a trial size c, reads the event function there, and moves by Newton's method inside a
bracket [a, b] with g(a) < 0 <= g(b) that Illinois regula falsi keeps shrinking. Each kernel
hands it its own step, event function and event rate. Inlined into the compiled loops
(``jit_leaf``): the same arithmetic as written out in place, and the functions handed in are
compile-time constants there (a compiled function handed one at run time could not be cached).
Those must be called, not inlined (``jit``): numba cannot inline a call with ``*args``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .jit import jit_leaf

EPS = 2.220446049250313e-16  # unit roundoff of a double


@jit_leaf
def event_tolerance(h: float, t: float) -> float:
    """How closely a crossing in a step of size ``h`` from time ``t`` is located: below a few
    ulps of t the switch time cannot be told apart (t + s rounds) and the event function sits
    at its rounding floor, so iterating further would only bisect noise."""
    return max(h * 1e-12, 2.0 * EPS * abs(t), 1e-18)


@jit_leaf
def false_position(a: float, b: float, fa: float, fb: float) -> float:
    """The regula falsi point of the bracket; its midpoint when rounding puts that point
    outside (a, b)."""
    c = (a * fb - b * fa) / (fb - fa)
    if not (a < c < b):
        c = 0.5 * (a + b)
    return c


@jit_leaf
def illinois_update(
    a: float, b: float, fa: float, fb: float, side: int, c: float, fc: float
) -> tuple[float, float, float, float, int]:
    """The bracket after reading g(c) = fc: c replaces the end of fc's sign; the end kept
    twice in a row has its value halved (Illinois), so the bracket shrinks from both sides.
    ``side`` says which end moved last (-1: b, 1: a, 0: none yet); returns (a, b, fa, fb,
    side)."""
    if fc >= 0.0:
        b, fb = c, fc
        if side == -1:
            fa *= 0.5
        side = -1
    else:
        a, fa = c, fc
        if side == 1:
            fb *= 0.5
        side = 1
    return a, b, fa, fb, side


@jit_leaf
def locate_crossing(
    step_to: Callable[..., None],
    event_at: Callable[..., float],
    event_rate_at: Callable[..., float],
    k: int,
    h: float,
    ga: float,
    gb: float,
    tol: float,
    args: tuple[Any, ...],
) -> float:
    """Smallest s in (0, h] with g_k(real step of size s) >= 0, to ``tol``, given g_k = ga < 0
    at the step's start and gb >= 0 at its end; on return the trial state is the step to it.

    ``step_to(s, *args)`` takes the real step of size s from the step's start into the trial
    state, ``event_at(k, *args)`` reads g_k there and ``event_rate_at(k, *args)`` its time
    derivative (0: no Newton step, the bracket alone). Newton's method on real steps (the
    step's end derivative gives ġ for free), kept inside the shrinking bracket and falling
    back to Illinois regula falsi when a Newton step would leave it."""
    a, b = 0.0, h
    fa, fb = ga, gb
    side = 0
    c = false_position(a, b, fa, fb)
    for _ in range(100):
        if not (a < c < b):  # a converged Newton step nudged onto an end of the bracket
            c = 0.5 * (a + b)
        step_to(c, *args)
        fc = event_at(k, *args)
        a, b, fa, fb, side = illinois_update(a, b, fa, fb, side, c, fc)
        if fc == 0.0 or b - a <= tol:
            break
        rate = event_rate_at(k, *args)
        newton = c - fc / rate if rate != 0.0 else -1.0
        if abs(newton - c) <= tol:
            # converged: step just past the root so the event has really happened
            c = min(b, newton + tol)
            if c == b:
                break
            continue
        if a < newton < b:
            c = newton
        else:
            c = false_position(a, b, fa, fb)
    if b != c:
        step_to(b, *args)
    return b
