"""Locating an event's zero crossing inside a step: the bracket both integrators shrink.

The arm's kernel (``kernel/events.py``, Newton inside the bracket) and the free body's
(``bodies/kernel.py``, the bracket alone) step from the start of the step that crossed an
event to a trial size c and read the event function there; these helpers keep the bracket
[a, b] with g(a) < 0 <= g(b) around the crossing by Illinois regula falsi. Inlined into the
compiled loops (``jit_leaf``): the same arithmetic as written out in place."""

from __future__ import annotations

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
