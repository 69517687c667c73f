"""Contact laws of one impact (docs/model.md): Hertz elastic compression, Jackson-Green
elasto-plastic compression, elastic restitution about a residual dent, and tanh-smoothed
Coulomb friction. Plain functions of the indentation so they test against closed forms.

Penetration δ = h - y_B is positive inside the surface. The force laws are zero for a
non-positive argument: that *is* the law (no adhesion), and it keeps trial stages of a
Runge-Kutta step that overshoot separation finite instead of producing NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .jit import jit_leaf as jit
from .layout import ELASTIC, ELASTOPLASTIC, RESTITUTION
from .scene.types import Material, reduced_modulus

YIELD_ONSET_FACTOR = 1.9  # the elastic phase ends at δ = 1.9 δc (Jackson-Green)

# A contact law's code in the compiled kernels' tables (the arm's surface table, the free
# body's pair table), by its name in a scene file. Every law runs the same phase machine
# (docs/model.md): free, elastic, elasto-plastic, restitution, free; a law decides which
# phases it enters and where it switches (``yield_margin``, ``law_residual``).
CONTACT_ELASTOPLASTIC, CONTACT_HERTZ, CONTACT_CONSTANT_COR, CONTACT_NONE = 0, 1, 2, 3
CONTACT_LAW_CODES = {
    'elastoplastic': CONTACT_ELASTOPLASTIC,
    'hertz': CONTACT_HERTZ,
    'constant_cor': CONTACT_CONSTANT_COR,
    'none': CONTACT_NONE,
}


@dataclass(frozen=True)
class ContactConstants:
    """Everything one tip/surface pairing needs, computed once per scene (docs/model.md)."""

    E: float  # reduced modulus [Pa]
    R: float  # reduced radius [m] (flat surface: the tip radius)
    S_y: float  # yield strength of the weaker material [Pa]
    nu: float  # Poisson ratio used in C_j (that of the weaker material)
    C_j: float
    delta_c: float  # critical interference at yield onset [m]
    P_c: float  # critical load [N]
    B: float

    @property
    def delta_yield(self) -> float:
        return YIELD_ONSET_FACTOR * self.delta_c


def contact_constants(arm: Material, surface: Material, tip_radius: float) -> ContactConstants:
    E = reduced_modulus(arm, surface)
    weaker = arm if arm.S_y <= surface.S_y else surface
    S_y, nu = weaker.S_y, weaker.nu
    R = tip_radius
    C_j = 1.295 * math.exp(0.736 * nu)
    delta_c = R * (math.pi * C_j * S_y / (2 * E)) ** 2
    P_c = 4.0 / 3.0 * (R / E) ** 2 * (math.pi * C_j * S_y / 2) ** 3
    B = 0.14 * math.exp(23 * S_y / E)
    return ContactConstants(E, R, S_y, nu, C_j, delta_c, P_c, B)


@jit
def hertz_force(delta: float, E: float, R: float) -> float:
    """Hertz sphere-on-flat: F = 4/3 E √R δ^1.5."""
    return 4.0 / 3.0 * E * math.sqrt(R) * delta * math.sqrt(delta) if delta > 0 else 0.0


@jit
def jackson_green(
    delta: float, delta_c: float, R: float, S_y: float, C_j: float, P_c: float, B: float
) -> float:
    """Elasto-plastic compression force, article eq. 12 with docs/model.md's a and H."""
    if delta <= 0:
        return 0.0
    ratio = delta / delta_c
    a = math.sqrt(R * delta * (delta / (YIELD_ONSET_FACTOR * delta_c)) ** B)
    hardness = S_y * (2.84 - 0.92 * (1 - math.cos(math.pi * a / R)))
    return P_c * (
        math.exp(-0.25 * ratio ** (5.0 / 12.0)) * ratio**1.5
        + 4 * hardness / (C_j * S_y) * (1 - math.exp(-(ratio ** (5.0 / 9.0)) / 25)) * ratio
    )


def jackson_green_force(delta: float, c: ContactConstants) -> float:
    return jackson_green(delta, c.delta_c, c.R, c.S_y, c.C_j, c.P_c, c.B)


@jit
def residual(delta_m: float, delta_c: float) -> float:
    """δr after unloading from δm (Etsion et al. fit, docs/model.md).

    The fit is for contacts that yielded (δm ≥ δc); below δc the contact stayed elastic and
    unloads along its loading curve, so δr = 0 — the fit itself would turn negative there."""
    if delta_m <= delta_c:
        return 0.0
    return delta_m * 1.02 * (1 - ((delta_m / delta_c + 5.9) / 6.9) ** -0.54)


def residual_indentation(delta_m: float, c: ContactConstants) -> float:
    return residual(delta_m, c.delta_c)


@jit
def restitution_radius(delta_m: float, delta_r: float, P_m: float, E: float) -> float:
    """Rr chosen so the restitution curve starts at (δm, Pm): Rr = (3Pm/4E)² / (δm-δr)³."""
    return (3 * P_m / (4 * E)) ** 2 / (delta_m - delta_r) ** 3


@jit
def restitution_force(delta: float, delta_r: float, E: float, R_r: float) -> float:
    return hertz_force(delta - delta_r, E, R_r)


@jit
def friction_force(normal_force: float, slip_velocity: float, mu: float, v_d: float) -> float:
    """Tangential force opposing slip: -μ |Fn| tanh(v/v_d) (docs/model.md fixes eq. 14's sign)."""
    return -mu * abs(normal_force) * math.tanh(slip_velocity / v_d)


# ------------------------------------------------------------------ the kernels' dispatch
# Both compiled integrators (the arm's kernel/, the free body's bodies/kernel.py) call these
# three for every law-dependent quantity of a contact, so a law is dispatched in one place.


@jit
def phase_normal_force(
    phase: int,
    delta: float,
    E: float,
    R: float,
    S_y: float,
    C_j: float,
    delta_c: float,
    P_c: float,
    B: float,
    delta_r: float,
    R_r: float,
) -> float:
    """The normal force at indentation δ in a contact phase: Hertz while elastic, Jackson-Green
    once yielded, the restitution curve about the dent δr (radius Rr) after the maximum
    compression; zero when free. A law's choice is in which phases it enters."""
    if phase == ELASTIC:
        return hertz_force(delta, E, R)
    if phase == ELASTOPLASTIC:
        return jackson_green(delta, delta_c, R, S_y, C_j, P_c, B)
    if phase == RESTITUTION:
        return restitution_force(delta, delta_r, E, R_r)
    return 0.0


@jit
def yield_margin(law: int, delta: float, delta_c: float) -> float:
    """The elastic phase's yield event function: rises through zero at the yield onset
    δ = 1.9 δc; -1 (never) for a law that does not yield."""
    if law == CONTACT_ELASTOPLASTIC:
        return delta - YIELD_ONSET_FACTOR * delta_c
    return -1.0


@jit
def law_residual(law: int, delta_m: float, delta_c: float, cor: float) -> float:
    """The residual indentation δr the restitution starts from after a maximum compression δm:
    the Etsion fit for the elasto-plastic law; for the constant-CoR law the δr at which the
    Hertz unloading from (δm, Pm) returns e² of the energy stored, so the contact's energetic
    CoR is e (it returns (2/5) Pm (δm - δr) of (2/5) Pm δm: δr = (1 - e²) δm); 0 (elastic
    unloading) for Hertz."""
    if law == CONTACT_ELASTOPLASTIC:
        return residual(delta_m, delta_c)
    if law == CONTACT_CONSTANT_COR:
        return (1.0 - cor**2) * delta_m
    return 0.0
