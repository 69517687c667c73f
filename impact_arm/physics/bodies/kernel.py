"""Compiled stepping of one free planar rigid body with several contact pairs.

The state is y = (x, z, θ, ẋ, ż, ω): the centre of mass and the orientation. Each corner is a
sphere of radius r centred at a body-frame point; each surface is a line through a point with
a unit normal n pointing into free space. Every (corner, surface) pair has its own phase
machine, the arm's (docs/model.md, physics/kernel/phases.py)::

    free --δ=0--> elastic --δ=1.9δc--> elasto-plastic --δ̇=0--> restitution --δ=δr--> free
    (elastic --δ̇=0--> restitution for a Hertz or constant-CoR law, or a gentle impact)

with the indentation δ = r - n·(c - p) of the corner centre c, measured from the pair's dent
(the residual indentation of its earlier impacts, kept while the corner stays below the
original surface). Several pairs may be in contact at once; their forces add up.

Stepping: adaptive Dormand-Prince 5(4). Every switch is located by regula falsi (Illinois)
on *real* steps from the start of the step that crossed it, as the arm's integrator does, and
every switch whose function is non-negative at the located state is applied there (two corners
landing together switch together). Functions take all their working arrays from the caller:
compiled without numba's reference counting (``jit.OPTIONS``), they cannot allocate.
"""

from __future__ import annotations

import math

import numpy as np

from ..contact import (
    YIELD_ONSET_FACTOR,
    friction_force,
    hertz_force,
    jackson_green,
    residual,
    restitution_force,
    restitution_radius,
)
from ..jit import jit, jit_leaf
from ..roots import event_tolerance, false_position, illinois_update

# pair phases
FREE, ELASTIC, ELASTOPLASTIC, RESTITUTION = 0, 1, 2, 3
# pair laws
LAW_ELASTOPLASTIC, LAW_HERTZ, LAW_CONSTANT_COR, LAW_NONE = 0, 1, 2, 3
# columns of the pair table (one row per corner x surface)
(
    PT_CORNER,
    PT_PX,
    PT_PZ,
    PT_NX,
    PT_NZ,
    PT_LAW,
    PT_E,
    PT_R,
    PT_SY,
    PT_CJ,
    PT_PC,
    PT_DC,
    PT_B,
    PT_MU,
    PT_VD,
    PT_COR,
    PT_SURFACE,
) = range(17)
PT_COLUMNS = 17
# columns of the pair state
CS_PHASE, CS_DM, CS_PM, CS_DR, CS_RR, CS_DENT, CS_PEAK = range(7)
CS_COLUMNS = 7
# body parameters
P_MASS, P_INERTIA, P_GRAVITY = range(3)
# event log columns: time, pair, kind, value 1..3 (max compression: δm, Pm, δr)
EV_CONTACT, EV_YIELD, EV_MAX, EV_SEPARATION = range(4)
LOG_COLUMNS = 6
# status codes of ``advance``
DONE, SETTLED, UNDERFLOW, BAD_RESIDUAL, LOG_FULL, BUDGET, NOT_FINITE = range(7)
# statistics: steps, rejected, right-hand side evaluations, events
ST_STEPS, ST_REJECTED, ST_RHS, ST_EVENTS = range(4)
EPS = 2.220446049250313e-16

# Dormand-Prince 5(4) tableau
C2, C3, C4, C5 = 0.2, 0.3, 0.8, 8.0 / 9.0
A21 = 0.2
A31, A32 = 3.0 / 40.0, 9.0 / 40.0
A41, A42, A43 = 44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0
A51, A52, A53, A54 = 19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0
A61, A62, A63, A64, A65 = (
    9017.0 / 3168.0,
    -355.0 / 33.0,
    46732.0 / 5247.0,
    49.0 / 176.0,
    -5103.0 / 18656.0,
)
B1, B3, B4, B5, B6 = 35.0 / 384.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0
E1, E3, E4, E5, E6, E7 = (
    71.0 / 57600.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
)


@jit_leaf
def pair_geometry(
    y: np.ndarray, corners: np.ndarray, PT: np.ndarray, CS: np.ndarray, k: int
) -> tuple[float, float, float, float, float, float]:
    """Pair k at state y: indentation from the dent, its rate, the contact point's offset
    from the centre of mass (dx, dz), the slip velocity along the surface and δ from the
    original surface."""
    c, s = math.cos(y[2]), math.sin(y[2])
    j = int(PT[k, PT_CORNER])
    bx, bz = corners[j, 0], corners[j, 1]
    rx, rz = c * bx - s * bz, s * bx + c * bz  # corner centre relative to the centre of mass
    nx, nz = PT[k, PT_NX], PT[k, PT_NZ]
    r = PT[k, PT_R]
    delta0 = r - (nx * (y[0] + rx - PT[k, PT_PX]) + nz * (y[1] + rz - PT[k, PT_PZ]))
    rate = -(nx * (y[3] - y[5] * rz) + nz * (y[4] + y[5] * rx))
    dx, dz = rx - r * nx, rz - r * nz  # the contact point, on the sphere along -n
    slip = nz * (y[3] - y[5] * dz) - nx * (y[4] + y[5] * dx)  # along t = (n_z, -n_x)
    return delta0 - CS[k, CS_DENT], rate, dx, dz, slip, delta0


@jit_leaf
def normal_force(delta: float, PT: np.ndarray, CS: np.ndarray, k: int) -> float:
    """The pair's normal force in its current phase (zero when free)."""
    phase = int(CS[k, CS_PHASE])
    if phase == ELASTIC:
        return hertz_force(delta, PT[k, PT_E], PT[k, PT_R])
    if phase == ELASTOPLASTIC:
        return jackson_green(
            delta, PT[k, PT_DC], PT[k, PT_R], PT[k, PT_SY], PT[k, PT_CJ], PT[k, PT_PC], PT[k, PT_B]
        )
    if phase == RESTITUTION:
        return restitution_force(delta, CS[k, CS_DR], PT[k, PT_E], CS[k, CS_RR])
    return 0.0


@jit
def rhs(
    y: np.ndarray, P: np.ndarray, corners: np.ndarray, PT: np.ndarray, CS: np.ndarray, f: np.ndarray
) -> None:
    """f = dy/dt: gravity along -z and the forces of every pair in contact."""
    fx, fz, torque = 0.0, -P[P_MASS] * P[P_GRAVITY], 0.0
    for k in range(PT.shape[0]):
        if CS[k, CS_PHASE] == FREE:
            continue
        delta, _, dx, dz, slip, _ = pair_geometry(y, corners, PT, CS, k)
        fn = normal_force(delta, PT, CS, k)
        ff = friction_force(fn, slip, PT[k, PT_MU], PT[k, PT_VD]) if PT[k, PT_MU] > 0 else 0.0
        nx, nz = PT[k, PT_NX], PT[k, PT_NZ]
        gx, gz = fn * nx + ff * nz, fn * nz - ff * nx
        fx += gx
        fz += gz
        torque += dx * gz - dz * gx
    f[0], f[1], f[2] = y[3], y[4], y[5]
    f[3], f[4], f[5] = fx / P[P_MASS], fz / P[P_MASS], torque / P[P_INERTIA]


@jit
def trial_step(
    y: np.ndarray,
    f0: np.ndarray,
    h: float,
    P: np.ndarray,
    corners: np.ndarray,
    PT: np.ndarray,
    CS: np.ndarray,
    K: np.ndarray,
    y1: np.ndarray,
    f1: np.ndarray,
    err: np.ndarray,
    stats: np.ndarray,
) -> None:
    """One Dormand-Prince step of size h from (y, f0): y1, f1 = f(y1) and the error estimate."""
    n = y.shape[0]
    for i in range(n):
        y1[i] = y[i] + h * A21 * f0[i]
    rhs(y1, P, corners, PT, CS, K[0])
    for i in range(n):
        y1[i] = y[i] + h * (A31 * f0[i] + A32 * K[0, i])
    rhs(y1, P, corners, PT, CS, K[1])
    for i in range(n):
        y1[i] = y[i] + h * (A41 * f0[i] + A42 * K[0, i] + A43 * K[1, i])
    rhs(y1, P, corners, PT, CS, K[2])
    for i in range(n):
        y1[i] = y[i] + h * (A51 * f0[i] + A52 * K[0, i] + A53 * K[1, i] + A54 * K[2, i])
    rhs(y1, P, corners, PT, CS, K[3])
    for i in range(n):
        y1[i] = y[i] + h * (
            A61 * f0[i] + A62 * K[0, i] + A63 * K[1, i] + A64 * K[2, i] + A65 * K[3, i]
        )
    rhs(y1, P, corners, PT, CS, K[4])
    for i in range(n):
        y1[i] = y[i] + h * (B1 * f0[i] + B3 * K[1, i] + B4 * K[2, i] + B5 * K[3, i] + B6 * K[4, i])
    rhs(y1, P, corners, PT, CS, f1)
    for i in range(n):
        err[i] = h * (
            E1 * f0[i] + E3 * K[1, i] + E4 * K[2, i] + E5 * K[3, i] + E6 * K[4, i] + E7 * f1[i]
        )
    stats[ST_RHS] += 6


@jit
def event_values(
    y: np.ndarray, corners: np.ndarray, PT: np.ndarray, CS: np.ndarray, g: np.ndarray
) -> None:
    """Two event functions per pair (slot 2k: contact, yield onset or separation; slot 2k+1:
    maximum compression); a switch happens when one rises through zero, -1 when unarmed."""
    for k in range(PT.shape[0]):
        a, b = -1.0, -1.0
        law = int(PT[k, PT_LAW])
        if law != LAW_NONE:
            delta, rate, _, _, _, _ = pair_geometry(y, corners, PT, CS, k)
            phase = int(CS[k, CS_PHASE])
            if phase == FREE:
                a = delta
            elif phase == ELASTIC:
                if law == LAW_ELASTOPLASTIC:
                    a = delta - YIELD_ONSET_FACTOR * PT[k, PT_DC]
                b = -rate
            elif phase == ELASTOPLASTIC:
                b = -rate
            else:
                a = CS[k, CS_DR] - delta
        g[2 * k], g[2 * k + 1] = a, b


@jit
def locate(
    y: np.ndarray,
    f0: np.ndarray,
    h: float,
    slot: int,
    ga: float,
    gb: float,
    tol: float,
    P: np.ndarray,
    corners: np.ndarray,
    PT: np.ndarray,
    CS: np.ndarray,
    K: np.ndarray,
    y1: np.ndarray,
    f1: np.ndarray,
    err: np.ndarray,
    g: np.ndarray,
    stats: np.ndarray,
) -> float:
    """Smallest s in (0, h] with g_slot(real step of size s) >= 0, by Illinois regula falsi
    in a shrinking bracket (bisection when it stalls)."""
    a, b, fa, fb = 0.0, h, ga, gb
    side = 0
    for _ in range(200):
        c = false_position(a, b, fa, fb)
        trial_step(y, f0, c, P, corners, PT, CS, K, y1, f1, err, stats)
        event_values(y1, corners, PT, CS, g)
        fc = g[slot]
        a, b, fa, fb, side = illinois_update(a, b, fa, fb, side, c, fc)
        if fc == 0.0 or b - a <= tol:
            break
    return b


@jit
def apply_event(
    t: float,
    y: np.ndarray,
    k: int,
    second: int,
    corners: np.ndarray,
    PT: np.ndarray,
    CS: np.ndarray,
    log: np.ndarray,
    nlog: np.ndarray,
) -> int:
    """Switch pair k's phase machine at its event (``second``: the maximum-compression slot);
    books the event in ``log``. Returns a status (``DONE`` when fine)."""
    delta, _, _, _, _, delta0 = pair_geometry(y, corners, PT, CS, k)
    phase = int(CS[k, CS_PHASE])
    law = int(PT[k, PT_LAW])
    kind = EV_CONTACT
    v1, v2, v3 = 0.0, 0.0, 0.0
    if second == 1:
        kind = EV_MAX
        fn = normal_force(delta, PT, CS, k)
        if law == LAW_ELASTOPLASTIC:
            dr = residual(delta, PT[k, PT_DC])
        elif law == LAW_CONSTANT_COR:
            # a Hertz unloading from (δm, Pm) returns (2/5) Pm (δm - δr) of the (2/5) Pm δm
            # stored: the pair's energetic CoR is e exactly when δr = (1 - e²) δm
            dr = (1.0 - PT[k, PT_COR] ** 2) * delta
        else:
            dr = 0.0
        CS[k, CS_DM], CS[k, CS_PM], CS[k, CS_DR] = delta, fn, dr
        if not (0.0 <= dr < delta):
            return BAD_RESIDUAL
        CS[k, CS_RR] = restitution_radius(delta, dr, fn, PT[k, PT_E])
        CS[k, CS_PEAK] = max(CS[k, CS_PEAK], fn)
        CS[k, CS_PHASE] = RESTITUTION
        v1, v2, v3 = delta, fn, dr
    elif phase == FREE:
        CS[k, CS_PHASE], CS[k, CS_PEAK] = ELASTIC, 0.0
    elif phase == ELASTIC:
        kind = EV_YIELD
        CS[k, CS_PHASE] = ELASTOPLASTIC
        v1 = delta
    else:
        kind = EV_SEPARATION
        # the corner leaves the dent's floor: keep it strictly below the corner, so the next
        # contact of this pair is seen rising through zero (as the arm keeps its levels)
        CS[k, CS_DENT] = max(
            CS[k, CS_DENT] + CS[k, CS_DR], delta0 + 4.0 * EPS * (abs(delta0) + PT[k, PT_R])
        )
        CS[k, CS_PHASE] = FREE
        v1, v2, v3 = CS[k, CS_PEAK], CS[k, CS_DM], CS[k, CS_DR]
    i = int(nlog[0])
    if i >= log.shape[0]:
        return LOG_FULL  # the caller drains the log before it can fill (``advance``)
    log[i, 0], log[i, 1], log[i, 2] = t, k, kind
    log[i, 3], log[i, 4], log[i, 5] = v1, v2, v3
    nlog[0] += 1
    return DONE


@jit
def advance(
    t: float,
    y: np.ndarray,
    t_end: float,
    P: np.ndarray,
    corners: np.ndarray,
    PT: np.ndarray,
    CS: np.ndarray,
    rtol: float,
    atol: float,
    max_step: float,
    settle: float,
    max_steps: int,
    log: np.ndarray,
    nlog: np.ndarray,
    trace: np.ndarray,
    ntrace: np.ndarray,
    W: np.ndarray,
    G: np.ndarray,
    stats: np.ndarray,
    memory: np.ndarray,
) -> tuple[float, int]:
    """Integrate y from t until t_end; returns (t, status). With ``settle`` > 0 it stops
    (``SETTLED``) once every pair has been free for ``settle`` seconds after a separation:
    the end of an impact, its bounces of other corners included. ``trace`` gets (t, y) at
    every accepted step while it has room. ``W`` is scratch (12 rows of the state's size),
    ``G`` three rows of event values. It returns ``LOG_FULL`` with every event applied and
    booked when fewer than two per pair fit in ``log`` (the caller drains it and calls again);
    ``memory`` keeps (time every pair became free, a separation happened) between calls."""
    n = y.shape[0]
    f0, y1, f1, err, y2, f2 = W[0], W[1], W[2], W[3], W[4], W[5]
    K = W[6:11]
    g0, g1, g2 = G[0], G[1], G[2]
    npairs = PT.shape[0]
    rhs(y, P, corners, PT, CS, f0)
    stats[ST_RHS] += 1
    event_values(y, corners, PT, CS, g0)
    h = min(max_step, t_end - t, 1e-4)
    t_free = memory[0]
    separated = memory[1] != 0.0
    steps = 0
    while t < t_end:
        if steps >= max_steps:
            return t, BUDGET
        steps += 1
        h = min(h, t_end - t, max_step)
        if t + h == t:
            return t, UNDERFLOW
        trial_step(y, f0, h, P, corners, PT, CS, K, y1, f1, err, stats)
        norm = 0.0
        for i in range(n):
            scale = atol + rtol * max(abs(y[i]), abs(y1[i]))
            norm += (err[i] / scale) ** 2
        norm = math.sqrt(norm / n)
        if not math.isfinite(norm):
            if h < 1e-15:
                return t, NOT_FINITE
            h *= 0.1
            stats[ST_REJECTED] += 1
            continue
        if norm > 1.0:
            h *= max(0.2, 0.9 * norm**-0.2)
            stats[ST_REJECTED] += 1
            continue
        stats[ST_STEPS] += 1
        h_next = h * min(5.0, 0.9 * norm**-0.2) if norm > 0 else 5.0 * h
        # which switches did this step cross?
        event_values(y1, corners, PT, CS, g1)
        s_min = h
        crossed = -1
        tol = event_tolerance(h, t)
        for slot in range(2 * npairs):
            if g0[slot] < 0.0 <= g1[slot]:
                s = locate(
                    y,
                    f0,
                    h,
                    slot,
                    g0[slot],
                    g1[slot],
                    tol,
                    P,
                    corners,
                    PT,
                    CS,
                    K,
                    y2,
                    f2,
                    err,
                    g2,
                    stats,
                )
                if crossed < 0 or s < s_min:
                    s_min, crossed = s, slot
        if crossed >= 0:
            if s_min != h:
                trial_step(y, f0, s_min, P, corners, PT, CS, K, y1, f1, err, stats)
                event_values(y1, corners, PT, CS, g1)
            t = t + s_min
            for i in range(n):
                y[i] = y1[i]
            # every switch that has happened at this state, in slot order
            for slot in range(2 * npairs):
                if g0[slot] < 0.0 <= g1[slot]:
                    status = apply_event(t, y, slot // 2, slot % 2, corners, PT, CS, log, nlog)
                    stats[ST_EVENTS] += 1
                    if status != DONE:
                        return t, status
                    if slot % 2 == 0 and CS[slot // 2, CS_PHASE] == FREE:
                        separated = True
            rhs(y, P, corners, PT, CS, f0)
            stats[ST_RHS] += 1
            h_next = min(h_next, max(s_min, 1e-9))
        else:
            t = t + h
            for i in range(n):
                y[i], f0[i] = y1[i], f1[i]
        for i in range(n):
            if not math.isfinite(y[i]):
                return t, NOT_FINITE
        # a corner back above the original surface has no dent left under it
        for k in range(npairs):
            if CS[k, CS_PHASE] == FREE and CS[k, CS_DENT] > 0.0:
                delta, _, _, _, _, delta0 = pair_geometry(y, corners, PT, CS, k)
                if delta0 < 0.0:
                    CS[k, CS_DENT] = 0.0
        event_values(y, corners, PT, CS, g0)
        i = int(ntrace[0])
        if i < trace.shape[0]:
            trace[i, 0] = t
            for j in range(n):
                trace[i, 1 + j] = y[j]
            ntrace[0] += 1
        memory[0], memory[1] = t_free, 1.0 if separated else 0.0
        if nlog[0] + 2 * npairs > log.shape[0]:
            return t, LOG_FULL
        if settle > 0.0 and separated:
            free = True
            for k in range(npairs):
                if CS[k, CS_PHASE] != FREE:
                    free = False
            if not free:
                t_free = -1.0
            elif t_free < 0.0:
                t_free = t
            memory[0] = t_free
            if t_free >= 0.0 and t - t_free >= settle:
                return t, SETTLED
        h = h_next
    return t, DONE
