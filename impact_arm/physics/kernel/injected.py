"""Stub of the names ``equations.py`` writes into each generated kernel module, so linters and
editors can follow the template parts. Never used at run time: the generator drops the
imports above each part's marker, and the values below are placeholders (a two-link shape).
"""

import math

from ..layout import shape_offsets

N = 2  # links
HAS_ACCEL = True  # accel() exists (closed-form q̈, N <= 3); else mass_and_rhs()
NM = 1  # surfaces on a compliant mount (each adds its plate's z, ż to the state)
HAS_MOUNT = True  # NM > 0

_offsets = shape_offsets(N, n_mount=NM)
SIZE = _offsets['SIZE']  # the longest state (PID integral states included)
NL = _offsets['NL']  # entries of the link-geometry block (N for rods: the lengths)
P_L, P_M, P_G, P_KP, P_KD, P_KI = (
    _offsets[k] for k in ('P_L', 'P_M', 'P_G', 'P_KP', 'P_KD', 'P_KI')
)
P_TDOWN, P_TUP, P_SWITCH = _offsets['P_TDOWN'], _offsets['P_TUP'], _offsets['P_SWITCH']
P_RTOL, P_ATOL, P_MAXSTEP = _offsets['P_RTOL'], _offsets['P_ATOL'], _offsets['P_MAXSTEP']
P_CRTOL, P_CATOL, P_SIZE = _offsets['P_CRTOL'], _offsets['P_CATOL'], _offsets['P_SIZE']
P_DAMP, P_FRIC, P_FVD, P_ARM = (_offsets[k] for k in ('P_DAMP', 'P_FRIC', 'P_FVD', 'P_ARM'))
P_JFRIC_ON, P_ARM_ON = _offsets['P_JFRIC_ON'], _offsets['P_ARM_ON']
R_T, R_Y, R_JT, R_JN, R_TAU, R_ACT, R_VTIP, R_FPEAK, R_SIZE = (
    _offsets[k]
    for k in ('R_T', 'R_Y', 'R_JT', 'R_JN', 'R_TAU', 'R_ACT', 'R_VTIP', 'R_FPEAK', 'R_SIZE')
)
W_GEN, W_TAU, W_ERR, W_RATE, W_MASS, SCRATCH = (
    _offsets[k] for k in ('W_GEN', 'W_TAU', 'W_ERR', 'W_RATE', 'W_MASS', 'SCRATCH')
)
TR_SIZE = _offsets['TR_SIZE']


# the sympy-generated functions (equations._derive_source); L: the link geometry (NL values:
# the lengths, for general links also centres of mass, inertias, contact point), m: masses
def accel(q, qd, Qx, L, m, g) -> tuple:
    """q̈ (N values) for generalized forces Qx besides gravity."""
    return (math.nan,) * N


def mass_and_rhs(q, qd, Qx, L, m, g) -> tuple:
    """M row-major (N*N values), then the right-hand side of M q̈ = Qx + Q_g - b (N values)."""
    return (math.nan,) * (N * N + N)


def mass_and_rhs_into(q, qd, Qx, L, m, g, S, out):
    """``mass_and_rhs`` written into arrays: M row-major into S[:N*N], the right-hand side
    into out[:N] (a long chain's N*N + N values are not returned as a tuple: numba types and
    lowers a big tuple, and each indexing of it, slowly)."""


def tip(q, qd, L) -> tuple:
    """(x, y, ẋ, ẏ) of the tip."""
    return (math.nan,) * 4


def tip_acceleration(q, qd, qdd, L) -> tuple:
    """(ẍ, ÿ) of the tip."""
    return (math.nan,) * 2


def tip_jacobian(q, L) -> tuple:
    """∂x_tip/∂q (N values), then ∂y_tip/∂q (N values)."""
    return (math.nan,) * (2 * N)


def gravity_forces(q, L, m, g) -> tuple:
    """Q_g: gravity's generalized forces (N values)."""
    return (math.nan,) * N


def link_energies(q, qd, L, m) -> tuple:
    """Kinetic energy of each link (N values)."""
    return (math.nan,) * N


def potential(q, L, m, g) -> tuple:
    """(V,): gravitational potential energy."""
    return (math.nan,)
