# Kernel part: the controller's state prediction (physics/prediction.py, ``StatePredictor``):
# the arm's free motion under joint torques held for whole periods, compiled.
# Template text (see kernel/__init__.py): the imports above the marker are for
# linters and editors only: the generated module's header provides those names.
# flake8: noqa: F401,F403,F405
import math

from ..control import q_law
from ..jit import jit, jit_leaf
from .injected import *
# --- template: equations.py copies what follows into the generated module ---


@jit_leaf
def free_accel(q, qd, generalized, L, m, g, out):
    """q̈ into ``out`` as ``StatePredictor._accel`` computes it: the closed form where there
    is one, else the mass matrix and right-hand side solved by their adjugate for three
    links (``prediction.solve3``, the same operations). False where that solve is singular
    or not finite (the predictor then asks LAPACK) or the arm needs LAPACK anyway (general
    links, N other than 3)."""
    if HAS_ACCEL:
        values = accel(q, qd, generalized, L, m, g)
        for i in range(N):
            out[i] = values[i]
        return True
    elif N == 3:  # (a constant: the other shapes compile without this branch)
        v = mass_and_rhs(q, qd, generalized, L, m, g)
        # M = [[s0, s1, s2], [s3, s4, s5], [s6, s7, s8]], right-hand side (r0, r1, r2)
        s0, s1, s2, s3, s4, s5, s6, s7, s8 = v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]
        r0, r1, r2 = v[9], v[10], v[11]
        c00, c01, c02 = s4 * s8 - s5 * s7, s2 * s7 - s1 * s8, s1 * s5 - s2 * s4
        c10, c11, c12 = s5 * s6 - s3 * s8, s0 * s8 - s2 * s6, s2 * s3 - s0 * s5
        c20, c21, c22 = s3 * s7 - s4 * s6, s1 * s6 - s0 * s7, s0 * s4 - s1 * s3
        det = s0 * c00 + s1 * c10 + s2 * c20
        if det == 0.0:
            return False
        x0 = (c00 * r0 + c01 * r1 + c02 * r2) / det
        x1 = (c10 * r0 + c11 * r1 + c12 * r2) / det
        x2 = (c20 * r0 + c21 * r1 + c22 * r2) / det
        if not (math.isfinite(x0) and math.isfinite(x1) and math.isfinite(x2)):
            return False
        out[0], out[1], out[2] = x0, x1, x2
        return True
    else:
        return False


@jit
def free_periods(y, torques, periods, substeps, h, L, m, g, work):
    """The state ``y`` (q, then q̇: 2N values) advanced in place by ``periods`` periods of
    ``substeps`` classical Runge-Kutta steps of ``h`` each, row k of ``torques`` (joint
    torques, N values) held over period k: ``StatePredictor._periods`` after its ``_hold``,
    the same operations in the same order, so the same bits. ``work``: 11 N scratch values.
    False (``y`` then holds no result) where an acceleration needs LAPACK (``free_accel``)."""
    generalized = work[0:N]
    x, v = work[N : 2 * N], work[2 * N : 3 * N]
    v2, v3, v4 = work[3 * N : 4 * N], work[4 * N : 5 * N], work[5 * N : 6 * N]
    a1, a2 = work[6 * N : 7 * N], work[7 * N : 8 * N]
    a3, a4 = work[8 * N : 9 * N], work[9 * N : 10 * N]
    at_q = work[10 * N : 11 * N]
    half, sixth = 0.5 * h, h / 6.0
    for i in range(N):
        x[i] = y[i]
        v[i] = y[N + i]
    for k in range(periods):
        for i in range(N):  # Q_i = τ_i - τ_(i+1), added to zeros
            generalized[i] = 0.0 + (torques[k, i] - (torques[k, i + 1] if i + 1 < N else 0.0))
        for _ in range(substeps):
            if not free_accel(x, v, generalized, L, m, g, a1):
                return False
            for i in range(N):
                v2[i] = v[i] + half * a1[i]
                at_q[i] = x[i] + half * v[i]
            if not free_accel(at_q, v2, generalized, L, m, g, a2):
                return False
            for i in range(N):
                v3[i] = v[i] + half * a2[i]
                at_q[i] = x[i] + half * v2[i]
            if not free_accel(at_q, v3, generalized, L, m, g, a3):
                return False
            for i in range(N):
                v4[i] = v[i] + h * a3[i]
                at_q[i] = x[i] + h * v3[i]
            if not free_accel(at_q, v4, generalized, L, m, g, a4):
                return False
            for i in range(N):
                x[i] = x[i] + sixth * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i])
                v[i] = v[i] + sixth * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i])
    for i in range(N):
        y[i] = x[i]
        y[N + i] = v[i]
    return True


@jit_leaf
def _held_q_law(y, torque, rows, periods, substeps, h, L, m, g, target, kp, kd, work, out):
    """The 'q' law (``q_law``, gravity from the model) on the state ``y`` leads to with
    ``torque`` held for ``periods`` periods, into ``out``; ``y`` is overwritten. False as
    ``free_periods``."""
    for k in range(periods):
        for i in range(N):
            rows[k, i] = torque[i]
    if not free_periods(y, rows, periods, substeps, h, L, m, g, work):
        return False
    q, qd, gravity = y[0:N], y[N : 2 * N], work[11 * N : 12 * N]
    values = gravity_forces(q, L, m, g)
    for i in range(N):
        gravity[i] = values[i]
    q_law(q, qd, target, kp, kd, gravity, out)
    return True


@jit
def implicit_q_law(y0, tau, periods, substeps, h, L, m, g, target, kp, kd, step, rows, work, out):
    """``StatePredictor.implicit_command`` for the 'q' law, the same operations in the same
    order (its Newton step, the Jacobian by forward differences of relative step ``step``,
    ``solve_small``'s elimination): the joint torques into ``out`` and 1; 0 where the step
    cannot be taken (the caller keeps ``tau``); -1 where an acceleration needs LAPACK (the
    caller computes it all in Python). ``y0``: the state (q, then q̇); ``rows``: ``periods``
    x N scratch; ``work``: 18 N + N² scratch."""
    y = work[12 * N : 14 * N]
    base, value, shifted = work[14 * N : 15 * N], work[15 * N : 16 * N], work[16 * N : 17 * N]
    a = work[17 * N : 17 * N + N * N]  # the system, row-major
    b = work[17 * N + N * N : 18 * N + N * N]
    for i in range(2 * N):
        y[i] = y0[i]
    if not _held_q_law(y, tau, rows, periods, substeps, h, L, m, g, target, kp, kd, work, base):
        return -1
    for j in range(N):
        size = abs(tau[j])
        step_j = step * (size if size > 1.0 else 1.0)  # (``max(1.0, size)``, NaN as it)
        for i in range(N):
            shifted[i] = tau[i]
        shifted[j] += step_j
        for i in range(2 * N):
            y[i] = y0[i]
        if not _held_q_law(
            y, shifted, rows, periods, substeps, h, L, m, g, target, kp, kd, work, value
        ):
            return -1
        for i in range(N):
            a[i * N + j] = (value[i] - base[i]) / step_j
    for i in range(N):  # rhs = base - J τ, each sum from 0 as Python's ``sum``
        s = 0.0
        for j in range(N):
            s += a[i * N + j] * tau[j]
        b[i] = base[i] - s
    for i in range(N):
        for j in range(N):
            a[i * N + j] = (1.0 if i == j else 0.0) - a[i * N + j]
    # Gaussian elimination with partial pivoting (the first of equal pivots)
    for k in range(N):
        pivot, largest = k, abs(a[k * N + k])
        for i in range(k + 1, N):
            if abs(a[i * N + k]) > largest:
                pivot, largest = i, abs(a[i * N + k])
        if a[pivot * N + k] == 0.0:
            return 0
        if pivot != k:
            for j in range(N):
                a[k * N + j], a[pivot * N + j] = a[pivot * N + j], a[k * N + j]
            b[k], b[pivot] = b[pivot], b[k]
        for i in range(k + 1, N):
            factor = a[i * N + k] / a[k * N + k]
            for j in range(k + 1, N):
                a[i * N + j] -= factor * a[k * N + j]
            b[i] -= factor * b[k]
    for i in range(N - 1, -1, -1):
        s = 0.0
        for j in range(i + 1, N):
            s += a[i * N + j] * out[j]
        out[i] = (b[i] - s) / a[i * N + i]
    for i in range(N):
        if not math.isfinite(out[i]):
            return 0
    return 1
