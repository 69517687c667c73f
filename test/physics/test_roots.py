"""The bracket both integrators locate their events with (physics/roots.py), against roots
known in closed form."""

import math

import pytest

from impact_arm.physics.roots import event_tolerance, false_position, illinois_update


def _locate(g, a, b, tol, illinois=True):
    """The bracket of the kernels' ``locate_crossing`` (physics/roots.py) without its Newton
    steps, on a plain function: (b, evaluations)."""
    fa, fb, side = g(a), g(b), 0
    for n in range(1, 201):
        c = false_position(a, b, fa, fb)
        fc = g(c)
        if illinois:
            a, b, fa, fb, side = illinois_update(a, b, fa, fb, side, c, fc)
        elif fc >= 0.0:
            b, fb = c, fc
        else:
            a, fa = c, fc
        if fc == 0.0 or b - a <= tol:
            return b, n
    return b, 200


@pytest.mark.parametrize(
    'g, a, b, root',
    [
        (lambda x: x**3 - 2.0, 0.0, 2.0, 2.0 ** (1 / 3)),
        (lambda x: math.exp(x) - 2.0, 0.0, 3.0, math.log(2.0)),
        (lambda x: math.sin(x), -1.0, 0.5, 0.0),
        (lambda x: 1.0 - 1.0 / (x * x), 0.1, 10.0, 1.0),  # steep at one end
    ],
)
def test_the_bracket_closes_on_the_root_from_its_rising_side(g, a, b, root):
    """g(a) < 0 <= g(b): the located point is the root within the tolerance, never before it
    (an event must have happened at the state it returns)."""
    tol = 1e-12
    located, evaluations = _locate(g, a, b, tol)
    assert g(located) >= 0.0
    assert root - 1e-15 <= located <= root + 2 * tol
    assert evaluations < 40


def test_illinois_halving_keeps_a_convex_function_from_stalling():
    """Plain regula falsi on a convex function moves one end only and stalls (the bracket
    never shrinks below the fixed end's distance); halving the kept end's value closes it."""
    g = lambda x: math.exp(4.0 * x) - 2.0  # noqa: E731
    tol = 1e-12
    _, plain = _locate(g, 0.0, 1.0, tol, illinois=False)
    located, illinois = _locate(g, 0.0, 1.0, tol)
    assert plain == 200  # never met the tolerance
    assert illinois < 30
    assert located == pytest.approx(math.log(2.0) / 4.0, abs=2 * tol)


def test_false_position_falls_back_to_the_midpoint_outside_the_bracket():
    assert false_position(0.0, 1.0, -1.0, 1.0) == 0.5
    assert false_position(0.0, 1.0, -1.0, 3.0) == 0.25
    # the secant point rounds onto b (a tiny value there): bisect instead
    assert false_position(0.0, 1.0, -1.0, 1e-30) == 0.5


def test_the_tolerance_is_a_few_ulps_of_the_time_or_a_fraction_of_the_step():
    assert event_tolerance(1e-3, 0.0) == pytest.approx(1e-15)
    assert event_tolerance(1e-3, 1e3) == 2.0 * 2.0**-52 * 1e3
    assert event_tolerance(0.0, 0.0) == 1e-18
