# Kernel part: the step methods (Dormand-Prince 5(4), from physics/dormand_prince.py, which the
# free body's kernel steps with too; Rosenbrock 4(3)) and the starting step size.
# Template text (see kernel/__init__.py): the imports above the marker are for
# linters and editors only: the generated module's header provides those names.
# flake8: noqa: F401,F403,F405
import math

from ..dormand_prince import dormand_prince_step
from ..jit import jit, jit_leaf
from ..layout import *
from .injected import *
from .rhs import rhs
# --- template: equations.py copies what follows into the generated module ---

EPS = 2.220446049250313e-16  # unit roundoff of a double
# Rosenbrock 4(3), Shampine's parameters (Kaps-Rentrop form, as in Numerical Recipes' stiff):
# four stages, three evaluations, A-stable. The right-hand side has no explicit time
# dependence (the control law switches at located events), so the dF/dt terms vanish.
RGAM = 1 / 2
RA21, RA31, RA32 = 2.0, 48 / 25, 6 / 25
RC21, RC31, RC32 = -8.0, 372 / 25, 12 / 5
RC41, RC42, RC43 = -112 / 125, -54 / 125, -2 / 5
RB1, RB2, RB3, RB4 = 19 / 9, 1 / 2, 25 / 108, 125 / 108
RE1, RE2, RE4 = 17 / 54, 7 / 36, 125 / 108
RA2X, RA3X = 1.0, 3 / 5
FD_STEP = 1.4901161193847656e-08  # sqrt(machine epsilon): finite-difference Jacobian


@jit
def rk_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W):
    """One Dormand-Prince step of size h: y1, f1 = f(t+h, y1) (FSAL) and the error vector."""
    dormand_prince_step(
        rhs, (P, I, SURF, C, levels, tau_held, stats, W), t, y, f0, h, y1, f1, err, K, work
    )


@jit_leaf
def lu_factor(A, piv):
    """In-place LU with partial pivoting (row k swapped with row piv[k]); False if singular."""
    n = A.shape[0]
    for k in range(n):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                p, big = i, abs(A[i, k])
        piv[k] = p
        if big == 0.0 or not math.isfinite(big):
            return False
        if p != k:
            for j in range(n):
                A[k, j], A[p, j] = A[p, j], A[k, j]
        for i in range(k + 1, n):
            A[i, k] /= A[k, k]
            for j in range(k + 1, n):
                A[i, j] -= A[i, k] * A[k, j]
    return True


@jit_leaf
def lu_solve(A, piv, b):
    """b := A⁻¹ b for A factored by lu_factor."""
    n = A.shape[0]
    for k in range(n):
        p = int(piv[k])
        if p != k:
            b[k], b[p] = b[p], b[k]
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= A[i, k] * b[k]
        b[i] = s
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, n):
            s -= A[i, k] * b[k]
        b[i] = s / A[i, i]


@jit
def ros_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W, JW):
    """One Rosenbrock 4(3) step of size h: y1, f1 = f(t+h, y1) and the error vector.

    The free flight is stiff (the controller's damping on the links' small inertia puts an
    eigenvalue near -1000 1/s), which caps an explicit step at ~3 ms whatever the tolerance;
    this linearly implicit step is not capped. JW holds the Jacobian (rows 0..n-1, by finite
    differences at (t, y), kept while JW[2n+1, 0] = 1: a rejected step or an event search
    restarts from the same point), the LU factors of I/(γh) - J (rows n..2n-1) and the
    pivots (row 2n)."""
    n = y.shape[0]
    J = JW[:n]
    LU = JW[n : 2 * n]
    piv = JW[2 * n]
    if JW[2 * n + 1, 0] == 0.0:
        for j in range(n):
            for i in range(n):
                work[i] = y[i]
            d = FD_STEP * max(1.0, abs(y[j]))
            work[j] = y[j] + d
            d = work[j] - y[j]  # the step actually representable
            rhs(t, work, f1, P, I, SURF, C, levels, tau_held, stats, W)
            for i in range(n):
                J[i, j] = (f1[i] - f0[i]) / d
        JW[2 * n + 1, 0] = 1.0
    diag = 1.0 / (RGAM * h)
    for i in range(n):
        for j in range(n):
            LU[i, j] = -J[i, j]
        LU[i, i] += diag
    if not lu_factor(LU, piv):
        for i in range(n):
            err[i] = math.inf  # rejected: the caller shrinks the step
        return
    g1, g2, g3, g4, tmp = K[0], K[1], K[2], K[3], K[4]
    for i in range(n):
        g1[i] = f0[i]
    lu_solve(LU, piv, g1)
    for i in range(n):
        work[i] = y[i] + RA21 * g1[i]
    rhs(t + RA2X * h, work, tmp, P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(n):
        g2[i] = tmp[i] + RC21 * g1[i] / h
    lu_solve(LU, piv, g2)
    for i in range(n):
        work[i] = y[i] + RA31 * g1[i] + RA32 * g2[i]
    rhs(t + RA3X * h, work, tmp, P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(n):
        g3[i] = tmp[i] + (RC31 * g1[i] + RC32 * g2[i]) / h
    lu_solve(LU, piv, g3)
    for i in range(n):
        g4[i] = tmp[i] + (RC41 * g1[i] + RC42 * g2[i] + RC43 * g3[i]) / h
    lu_solve(LU, piv, g4)
    for i in range(n):
        y1[i] = y[i] + RB1 * g1[i] + RB2 * g2[i] + RB3 * g3[i] + RB4 * g4[i]
        err[i] = RE1 * g1[i] + RE2 * g2[i] + RE4 * g4[i]
    rhs(t + h, y1, f1, P, I, SURF, C, levels, tau_held, stats, W)


@jit_leaf
def rosenbrock_now(I, C):
    """Whether the current phase steps with Rosenbrock (free flight, when chosen)."""
    return I[I_METHOD] == METHOD_ROSENBROCK and int(C[C_PHASE]) == FREE


@jit
def trial_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W, JW):
    """The step of the current phase's method: Rosenbrock in free flight when chosen, else
    Dormand-Prince (contact forces are not smooth enough for a linearly implicit step)."""
    if rosenbrock_now(I, C):
        ros_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W, JW)
    else:
        rk_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W)


@jit_leaf
def phase_tolerances(P, C):
    """(rtol, atol) of the current phase: contact phases have their own (see PhaseIntegrator)."""
    if int(C[C_PHASE]) != FREE:
        return P[P_CRTOL], P[P_CATOL]
    return P[P_RTOL], P[P_ATOL]


@jit
def initial_step(t, y, f0, P, I, SURF, C, levels, tau_held, stats, W, work, f1):
    """Hairer's starting step size: the phase just entered may be far stiffer than the last."""
    rtol, atol = phase_tolerances(P, C)
    max_step = P[P_MAXSTEP]
    size = y.shape[0]
    d0 = 0.0
    d1 = 0.0
    for i in range(size):
        scale = atol + rtol * abs(y[i])
        d0 += (y[i] / scale) ** 2
        d1 += (f0[i] / scale) ** 2
    d0 = math.sqrt(d0 / size)
    d1 = math.sqrt(d1 / size)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    for i in range(size):
        work[i] = y[i] + h0 * f0[i]
    rhs(t + h0, work, f1, P, I, SURF, C, levels, tau_held, stats, W)
    d2 = 0.0
    for i in range(size):
        scale = atol + rtol * abs(y[i])
        d2 += ((f1[i] - f0[i]) / scale) ** 2
    d2 = math.sqrt(d2 / size) / h0
    if max(d1, d2) <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** 0.2
    return min(100 * h0, h1, max_step)
