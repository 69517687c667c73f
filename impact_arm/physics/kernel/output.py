# Kernel part: dense output: the state between step ends (Dormand-Prince quartic or cubic Hermite)
# and the rows written on the output time grid.
# Template text (see kernel/__init__.py): the imports above the marker are for
# linters and editors only: the generated module's header provides those names.
# flake8: noqa: F401,F403,F405
from ..dormand_prince import (
    D12,
    D13,
    D14,
    D32,
    D33,
    D34,
    D42,
    D43,
    D44,
    D52,
    D53,
    D54,
    D62,
    D63,
    D64,
    D72,
    D73,
    D74,
)
from ..jit import jit
from ..layout import *
from .injected import *
from .rhs import control_torque
from .steps import EPS
# --- template: equations.py copies what follows into the generated module ---


@jit
def interpolate(t0, h, ts, y0, f0, y1, f1, K, quartic, out, at):
    """The state at ts in [t0, t0 + h] into out[at:at + size]: the Dormand-Prince quartic
    when K holds this step's stages (``quartic``), else the cubic Hermite of the two ends."""
    size = y0.shape[0]
    s = (ts - t0) / h
    if quartic:
        s2 = s * s
        b1 = s + s2 * (D12 + s * (D13 + s * D14))
        b3 = s2 * (D32 + s * (D33 + s * D34))
        b4 = s2 * (D42 + s * (D43 + s * D44))
        b5 = s2 * (D52 + s * (D53 + s * D54))
        b6 = s2 * (D62 + s * (D63 + s * D64))
        b7 = s2 * (D72 + s * (D73 + s * D74))
        for i in range(size):
            out[at + i] = y0[i] + h * (
                b1 * f0[i] + b3 * K[1, i] + b4 * K[2, i] + b5 * K[3, i] + b6 * K[4, i] + b7 * f1[i]
            )
    else:
        h00 = (1.0 + 2.0 * s) * (1.0 - s) ** 2
        h10 = s * (1.0 - s) ** 2
        h01 = s * s * (3.0 - 2.0 * s)
        h11 = s * s * (s - 1.0)
        for i in range(size):
            out[at + i] = h00 * y0[i] + h * h10 * f0[i] + h01 * y1[i] + h * h11 * f1[i]


@jit
def emit_output(t0, h, y0, f0, y1, f1, K, quartic, P, I, C, tau_held, O, out, scratch):
    """Output rows for the grid times k dt in (t0, t0 + h] (k = O[O_NEXT], dt = O[O_DT];
    O[O_ROWS] rows used): t, the state, the contact impulse since the previous row (then reset), the torque
    acting, whether the actuators act, the tip velocity and the peak normal contact force since
    the previous row (layout R_*). False when ``out``
    is full."""
    size = y0.shape[0]
    dt = O[O_DT]
    t1 = t0 + h
    eps = 4 * EPS * max(1.0, abs(t1))
    while True:
        ts = O[O_NEXT] * dt
        if ts > t1 + eps:
            return True
        row_index = int(O[O_ROWS])
        if row_index >= out.shape[0]:
            return False
        row = out[row_index]
        row[R_T] = ts
        state = row[R_Y : R_Y + size]
        if abs(ts - t1) <= eps:
            for i in range(size):
                state[i] = y1[i]
        else:
            # offset 0 into the row's state, as the stepping loop's calls: one compiled
            # specialisation (numba compiles one per literal offset)
            interpolate(t0, h, ts, y0, f0, y1, f1, K, quartic, state, 0)
        row[R_JT], row[R_JN] = C[C_JT], C[C_JN]
        C[C_JT] = 0.0
        C[C_JN] = 0.0
        # the peak since the previous row; the next interval starts from the force acting at
        # this row (contact steps end on the rows, so the last contact point is this one)
        row[R_FPEAK] = C[C_PERIOD_PEAK]
        C[C_PERIOD_PEAK] = C[C_IMP_FN] if C[C_PHASE] != FREE else 0.0
        acting = control_torque(
            state, P, I, C, tau_held, row[R_TAU : R_TAU + N], scratch[:N], scratch[N : 2 * N]
        )
        row[R_ACT] = 1.0 if acting else 0.0
        v = tip(state[:N], state[N : 2 * N], P[P_L : P_L + NL])
        row[R_VTIP], row[R_VTIP + 1] = v[2], v[3]
        O[O_NEXT] += 1.0
        O[O_ROWS] += 1.0
