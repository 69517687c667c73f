"""A sphere dropped normally on a flat surface: the contact laws and phase machine of
``contact.py`` alone, no arm. One degree of freedom, the indentation δ (positive into the
surface), m δ̈ = -F(δ), no gravity during the contact (mg is 1e-5 of the contact force here).

Phases as docs/model.md and the kernel's ``apply_event``: Hertz compression until δ = 1.9 δc
(elasto-plastic surfaces) or δ̇ = 0; Jackson-Green compression until δ̇ = 0; there δm, Pm,
δr (Etsion et al.'s fit; 0 for a Hertz surface) and Rr; elastic restitution about δr until
δ = δr, separation. Integrated with scipy's DOP853 and terminal events, to tolerances far
below the 1 % the published comparisons need, so the numbers are the laws', not the
integrator's. What ``impact-arm study contact`` compares with closed forms (docs/studies.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import math
from dataclasses import dataclass

from .contact import (
    ContactConstants,
    hertz_force,
    jackson_green_force,
    residual_indentation,
    restitution_force,
    restitution_radius,
)
from .errors import SimulationError
from .scene import Material

# the wall of a "rigid wall" test: stiffer and stronger than any sphere by 1e19, so that
# E* = E/(1 - ν²) of the sphere to rounding, through the same contact_constants as a scene
RIGID = Material(E=1e30, nu=0.0, S_y=1e30)


@dataclass(frozen=True)
class Drop:
    speed: float  # impact speed [m/s]
    rebound: float  # separation speed [m/s]
    delta_m: float  # maximum indentation [m]
    F_max: float  # maximum force [N]
    delta_r: float  # residual indentation [m]
    duration: float  # contact time [s]
    yielded: bool  # the Jackson-Green phase was entered

    @property
    def cor(self) -> float:
        return self.rebound / self.speed


def sphere_mass(radius: float, density: float) -> float:
    return 4.0 / 3.0 * math.pi * radius**3 * density


def drop(
    c: ContactConstants, mass: float, speed: float, law: str = 'elastoplastic', rtol: float = 1e-11
) -> Drop:
    """One normal impact at ``speed`` of a ``mass`` on the pairing ``c``."""
    from scipy.integrate import solve_ivp

    def phase(
        force: Callable[[float], float],
        events: Sequence[Any],  # event functions with solve_ivp's attributes
        y0: Sequence[float],
        t0: float,
    ) -> tuple[int, float, Any]:
        def rhs(t: float, y: Sequence[float]) -> tuple[float, float]:
            return (y[1], -force(y[0]) / mass)

        for event in events:
            event.terminal = True
        # the longest phase is shorter than half a Hertz period at this speed (times 10)
        span = 10 * 3 * (mass**2 / (c.E**2 * c.R * speed)) ** 0.2
        # absolute floors: a nanometre of indentation, a thousandth of the speed
        sol = solve_ivp(
            rhs,
            (t0, t0 + span),
            y0,
            method='DOP853',
            rtol=rtol,
            atol=[rtol * 1e-9, rtol * 1e-3 * speed],
            events=events,
        )
        for k, times in enumerate(sol.t_events):
            if len(times):
                return k, sol.t_events[k][0], sol.y_events[k][0]
        raise SimulationError(f'sphere drop at {speed:g} m/s: no phase end within {span:.3g} s')

    def at_rest(t: float, y: Sequence[float]) -> float:
        return y[1]

    at_rest.direction = -1.0  # type: ignore[attr-defined]  # read by solve_ivp
    y, t, yielded = (0.0, speed), 0.0, False
    elastic = lambda d: hertz_force(d, c.E, c.R)  # noqa: E731
    if law == 'elastoplastic':

        def onset(t: float, y: Sequence[float]) -> float:
            return y[0] - c.delta_yield

        which, t, y = phase(elastic, [at_rest, onset], y, t)
        if which == 1:  # yielded: Jackson-Green until the sphere stops
            yielded = True
            plastic = lambda d: jackson_green_force(d, c)  # noqa: E731
            _, t, y = phase(plastic, [at_rest], y, t)
            elastic = plastic  # the law that holds at maximum compression
    else:
        _, t, y = phase(elastic, [at_rest], y, t)
    delta_m = y[0]
    P_m = elastic(delta_m)
    delta_r = residual_indentation(delta_m, c) if law == 'elastoplastic' else 0.0
    if not 0.0 <= delta_r < delta_m:
        raise SimulationError(
            f'sphere drop at {speed:g} m/s: delta_r = {delta_r:.4g} m is '
            f'outside [0, delta_m = {delta_m:.4g} m): beyond the fit'
        )
    R_r = restitution_radius(delta_m, delta_r, P_m, c.E)

    def separated(t: float, y: Sequence[float]) -> float:
        return y[0] - delta_r

    separated.direction = -1.0  # type: ignore[attr-defined]  # read by solve_ivp
    _, t, y = phase(lambda d: restitution_force(d, delta_r, c.E, R_r), [separated], y, t)
    return Drop(speed, -y[1], delta_m, P_m, delta_r, t, yielded)


# --- closed forms ----------------------------------------------------------------------------
HERTZ_TIME_FACTOR = 2 * 0.4 * math.gamma(0.4) * math.gamma(0.5) / math.gamma(0.9)  # 2.9432


def hertz_closed_form(c: ContactConstants, mass: float, speed: float) -> dict:
    """Hertz's elastic impact: ½ m V² = (8/15) E* √R δm^{5/2}; F_max = (4/3) E* √R δm^{3/2};
    contact time 2 (δm/V) ∫₀¹ (1 - x^{5/2})^{-1/2} dx = 2.9432 δm / V (e.g. Johnson, Contact
    Mechanics, 1985, §11.4)."""
    delta_m = (15 * mass * speed**2 / (16 * c.E * math.sqrt(c.R))) ** 0.4
    return {
        'delta_m': delta_m,
        'F_max': hertz_force(delta_m, c.E, c.R),
        'duration': HERTZ_TIME_FACTOR * delta_m / speed,
    }


def yield_speed(c: ContactConstants, mass: float) -> float:
    """The impact speed whose Hertz indentation is δc (the peak pressure reaches C S_y):
    ½ m V_y² = (8/15) E* √R δc^{5/2}. For a sphere on a rigid or like surface this is
    Thornton's V_y = 1.56 (p_y⁵ / (E*⁴ ρ))^{1/2} with his limiting pressure p_y = C S_y."""
    return math.sqrt(16 / 15 * c.E * math.sqrt(c.R) * c.delta_c**2.5 / mass)


def thornton_cor(ratio: float) -> float:
    """Thornton (1997), J. Appl. Mech. 64, 383-386, eq. for V > V_y (``ratio`` = V / V_y):
    e = √(6√3/5) √(1 - (V_y/V)²/6) [ (V_y/V) / ((V_y/V) + 2 √(6/5 - (V_y/V)²/5)) ]^{1/4};
    e = 1 at and below V_y."""
    if ratio <= 1.0:
        return 1.0
    r = 1.0 / ratio
    return (
        math.sqrt(6 * math.sqrt(3) / 5)
        * math.sqrt(1 - r * r / 6)
        * (r / (r + 2 * math.sqrt(6 / 5 - r * r / 5))) ** 0.25
    )


def energy_balance_cor(c: ContactConstants, mass: float, speed: float) -> float:
    """The same laws without time integration: δm from ½ m V² = ∫₀^δm F dδ (quadrature and a
    root), the rebound energy of the restitution curve (2/5) Pm (δm - δr), e = √(ratio)."""
    from scipy.integrate import quad
    from scipy.optimize import brentq

    d_y = c.delta_yield

    def loading(d: float) -> float:
        return hertz_force(d, c.E, c.R) if d <= d_y else jackson_green_force(d, c)

    def work(d: float) -> float:
        if d <= d_y:
            return 0.4 * hertz_force(d, c.E, c.R) * d
        return (
            0.4 * hertz_force(d_y, c.E, c.R) * d_y
            + quad(lambda x: jackson_green_force(x, c), d_y, d, epsabs=0, epsrel=1e-12, limit=200)[
                0
            ]
        )

    kinetic = 0.5 * mass * speed**2
    high = c.R
    delta_m = brentq(lambda d: work(d) - kinetic, 0.0, high, xtol=1e-16, rtol=1e-14)
    delta_r = residual_indentation(delta_m, c)
    return math.sqrt(0.4 * loading(delta_m) * (delta_m - delta_r) / kinetic)
