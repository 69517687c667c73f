"""Compiled stepping of one free planar rigid body with several contact pairs.

The state is y = (x, z, θ, ẋ, ż, ω): the centre of mass and the orientation. Each corner is a
sphere of radius r centred at a body-frame point; each surface is a line through a point with
a unit normal n pointing into free space. Every (corner, surface) pair runs the arm's phase
machine (docs/model.md, physics/contact_phases.py)::

    free --δ=0--> elastic --δ=1.9δc--> elasto-plastic --δ̇=0--> restitution --δ=δr--> free
    (elastic --δ̇=0--> restitution for a Hertz or constant-CoR law, or a gentle impact)

with the indentation δ = r - n·(c - p) of the corner centre c, measured from the pair's dent
(the residual indentation of its earlier impacts, kept while the corner stays below the
original surface). Several pairs may be in contact at once; their forces add up.

What this module adds to the arm's machinery is the body: its state, the pairs' geometry and
their bookkeeping. The step is the arm's Dormand-Prince 5(4) (physics/dormand_prince.py), the
contact forces and switch quantities the arm's per-law dispatch (physics/contact.py), each
switch is located as the arm locates its own (physics/roots.py ``locate_crossing``: Newton on
*real* steps from the start of the step that crossed it, inside an Illinois bracket), and
every switch whose function is non-negative at the located state is applied there (two corners
landing together switch together). Functions take all their working arrays from the caller:
compiled without numba's reference counting (``jit.OPTIONS``), they cannot allocate.
"""

from __future__ import annotations

import math

import numpy as np

from ..contact import CONTACT_NONE, friction_force, phase_normal_force
from ..contact_phases import max_compression, phase_events
from ..dormand_prince import dormand_prince_step, error_norm
from ..jit import jit, jit_leaf
from ..layout import ELASTIC, ELASTOPLASTIC, FREE, RESTITUTION
from ..roots import event_tolerance, locate_crossing

# pair phases: the arm's (layout.FREE ... RESTITUTION); pair laws: contact.CONTACT_LAW_CODES
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
# event kinds, in ``phase_events``' order: pair k's event functions are slots 4k ... 4k+3
EV_CONTACT, EV_YIELD, EV_MAX, EV_SEPARATION = range(4)
EVENTS_PER_PAIR = 4
# event log columns: time, pair, kind, value 1..3 (max compression: δm, Pm, δr)
LOG_COLUMNS = 6
# status codes of ``advance``
DONE, SETTLED, UNDERFLOW, BAD_RESIDUAL, LOG_FULL, BUDGET, NOT_FINITE = range(7)
# statistics: steps, rejected, right-hand side evaluations, events
ST_STEPS, ST_REJECTED, ST_RHS, ST_EVENTS = range(4)
EPS = 2.220446049250313e-16


@jit_leaf
def corner_offset(
    y: np.ndarray, corners: np.ndarray, PT: np.ndarray, k: int
) -> tuple[float, float]:
    """Pair k's corner centre relative to the centre of mass, in the world frame."""
    c, s = math.cos(y[2]), math.sin(y[2])
    j = int(PT[k, PT_CORNER])
    bx, bz = corners[j, 0], corners[j, 1]
    return c * bx - s * bz, s * bx + c * bz


@jit_leaf
def pair_geometry(
    y: np.ndarray, corners: np.ndarray, PT: np.ndarray, CS: np.ndarray, k: int
) -> tuple[float, float, float, float, float, float]:
    """Pair k at state y: indentation from the dent, its rate, the contact point's offset
    from the centre of mass (dx, dz), the slip velocity along the surface and δ from the
    original surface."""
    rx, rz = corner_offset(y, corners, PT, k)
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
    return phase_normal_force(
        int(CS[k, CS_PHASE]),
        delta,
        PT[k, PT_E],
        PT[k, PT_R],
        PT[k, PT_SY],
        PT[k, PT_CJ],
        PT[k, PT_DC],
        PT[k, PT_PC],
        PT[k, PT_B],
        CS[k, CS_DR],
        CS[k, CS_RR],
    )


@jit
def rhs(
    t: float,
    y: np.ndarray,
    f: np.ndarray,
    P: np.ndarray,
    corners: np.ndarray,
    PT: np.ndarray,
    CS: np.ndarray,
    stats: np.ndarray,
) -> None:
    """f = dy/dt: gravity along -z and the forces of every pair in contact (t: the step's
    signature, ``dormand_prince_step``; nothing here depends on it)."""
    stats[ST_RHS] += 1
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
    work: np.ndarray,
    stats: np.ndarray,
) -> None:
    """One Dormand-Prince step of size h from (y, f0): y1, f1 = f(y1) and the error estimate
    (``work``: scratch of the state's size)."""
    dormand_prince_step(rhs, (P, corners, PT, CS, stats), 0.0, y, f0, h, y1, f1, err, K, work)


@jit
def event_values(
    y: np.ndarray, corners: np.ndarray, PT: np.ndarray, CS: np.ndarray, g: np.ndarray
) -> None:
    """The event functions of every pair's phase (``phase_events``: slots 4k ... 4k+3 of pair
    k, by kind); a switch happens when one rises through zero, -1 when unarmed."""
    for k in range(PT.shape[0]):
        law = int(PT[k, PT_LAW])
        at = EVENTS_PER_PAIR * k
        if law == CONTACT_NONE:  # no geometry to read: nothing is armed
            g[at], g[at + 1], g[at + 2], g[at + 3] = -1.0, -1.0, -1.0, -1.0
            continue
        delta, rate, _, _, _, _ = pair_geometry(y, corners, PT, CS, k)
        g[at], g[at + 1], g[at + 2], g[at + 3] = phase_events(
            int(CS[k, CS_PHASE]), law, delta, -rate, PT[k, PT_DC], CS[k, CS_DR]
        )


@jit_leaf
def event_rate(
    y: np.ndarray, f: np.ndarray, slot: int, corners: np.ndarray, PT: np.ndarray
) -> float:
    """Time derivative of event function ``slot`` at state y with derivative f (for Newton):
    ±δ̇ for the contact, yield and separation, -δ̈ for the maximum compression."""
    k, kind = slot // EVENTS_PER_PAIR, slot % EVENTS_PER_PAIR
    rx, rz = corner_offset(y, corners, PT, k)
    nx, nz = PT[k, PT_NX], PT[k, PT_NZ]
    rate = -(nx * (y[3] - y[5] * rz) + nz * (y[4] + y[5] * rx))
    if kind == EV_CONTACT or kind == EV_YIELD:
        return rate
    if kind == EV_SEPARATION:
        return -rate
    # δ̈ = -n·(a + α × r - ω² r): the corner centre's acceleration along -n
    w2 = y[5] * y[5]
    return nx * (f[3] - f[5] * rz - w2 * rx) + nz * (f[4] + f[5] * rx - w2 * rz)


@jit
def step_to(
    s: float,
    y: np.ndarray,
    f0: np.ndarray,
    P: np.ndarray,
    corners: np.ndarray,
    PT: np.ndarray,
    CS: np.ndarray,
    K: np.ndarray,
    y1: np.ndarray,
    f1: np.ndarray,
    err: np.ndarray,
    work: np.ndarray,
    g: np.ndarray,
    stats: np.ndarray,
) -> None:
    """``locate_crossing``'s trial: the real step of size s from (y, f0) into y1, f1."""
    trial_step(y, f0, s, P, corners, PT, CS, K, y1, f1, err, work, stats)


@jit
def event_at(
    slot: int,
    y: np.ndarray,
    f0: np.ndarray,
    P: np.ndarray,
    corners: np.ndarray,
    PT: np.ndarray,
    CS: np.ndarray,
    K: np.ndarray,
    y1: np.ndarray,
    f1: np.ndarray,
    err: np.ndarray,
    work: np.ndarray,
    g: np.ndarray,
    stats: np.ndarray,
) -> float:
    """``locate_crossing``'s event function ``slot`` at the trial state."""
    event_values(y1, corners, PT, CS, g)
    return g[slot]


@jit
def event_rate_at(
    slot: int,
    y: np.ndarray,
    f0: np.ndarray,
    P: np.ndarray,
    corners: np.ndarray,
    PT: np.ndarray,
    CS: np.ndarray,
    K: np.ndarray,
    y1: np.ndarray,
    f1: np.ndarray,
    err: np.ndarray,
    work: np.ndarray,
    g: np.ndarray,
    stats: np.ndarray,
) -> float:
    """``locate_crossing``'s ġ at the trial state, from the step's end derivative."""
    return event_rate(y1, f1, slot, corners, PT)


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
    work: np.ndarray,
    g: np.ndarray,
    stats: np.ndarray,
) -> float:
    """Smallest s in (0, h] with g_slot(real step of size s) >= 0 (the arm's
    ``locate_crossing``); y1, f1 hold the step to it."""
    args = (y, f0, P, corners, PT, CS, K, y1, f1, err, work, g, stats)
    return locate_crossing(step_to, event_at, event_rate_at, slot, h, ga, gb, tol, args)


@jit
def apply_event(
    t: float,
    y: np.ndarray,
    k: int,
    kind: int,
    corners: np.ndarray,
    PT: np.ndarray,
    CS: np.ndarray,
    log: np.ndarray,
    nlog: np.ndarray,
) -> int:
    """Switch pair k's phase machine at its event of ``kind`` (``EV_*``); books the event in
    ``log``. Returns a status (``DONE`` when fine)."""
    delta, _, _, _, _, delta0 = pair_geometry(y, corners, PT, CS, k)
    v1, v2, v3 = 0.0, 0.0, 0.0
    if kind == EV_MAX:
        fn = normal_force(delta, PT, CS, k)
        dr, rr, valid = max_compression(
            int(PT[k, PT_LAW]), delta, fn, PT[k, PT_E], PT[k, PT_DC], PT[k, PT_COR]
        )
        CS[k, CS_DM], CS[k, CS_PM], CS[k, CS_DR] = delta, fn, dr
        if not valid:
            return BAD_RESIDUAL
        CS[k, CS_RR] = rr
        CS[k, CS_PEAK] = max(CS[k, CS_PEAK], fn)
        CS[k, CS_PHASE] = RESTITUTION
        v1, v2, v3 = delta, fn, dr
    elif kind == EV_CONTACT:
        CS[k, CS_PHASE], CS[k, CS_PEAK] = ELASTIC, 0.0
    elif kind == EV_YIELD:
        CS[k, CS_PHASE] = ELASTOPLASTIC
        v1 = delta
    else:
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
    ``G`` three rows of event values (``EVENTS_PER_PAIR`` per pair). It returns ``LOG_FULL``
    with every event applied and booked when fewer than two per pair fit in ``log`` (the
    caller drains it and calls again);
    ``memory`` keeps (time every pair became free, a separation happened) between calls."""
    n = y.shape[0]
    f0, y1, f1, err, y2, f2 = W[0], W[1], W[2], W[3], W[4], W[5]
    K, work = W[6:11], W[11]
    g0, g1, g2 = G[0], G[1], G[2]
    npairs = PT.shape[0]
    rhs(t, y, f0, P, corners, PT, CS, stats)
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
        trial_step(y, f0, h, P, corners, PT, CS, K, y1, f1, err, work, stats)
        norm = error_norm(err, y, y1, rtol, atol)
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
        for slot in range(EVENTS_PER_PAIR * npairs):
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
                    work,
                    g2,
                    stats,
                )
                if crossed < 0 or s < s_min:
                    s_min, crossed = s, slot
        if crossed >= 0:
            if s_min != h:
                trial_step(y, f0, s_min, P, corners, PT, CS, K, y1, f1, err, work, stats)
                event_values(y1, corners, PT, CS, g1)
            t = t + s_min
            for i in range(n):
                y[i] = y1[i]
            # every switch that has happened at this state, in slot order
            for slot in range(EVENTS_PER_PAIR * npairs):
                if g0[slot] < 0.0 <= g1[slot]:
                    kind = slot % EVENTS_PER_PAIR
                    k = slot // EVENTS_PER_PAIR
                    status = apply_event(t, y, k, kind, corners, PT, CS, log, nlog)
                    stats[ST_EVENTS] += 1
                    if status != DONE:
                        return t, status
                    if kind == EV_SEPARATION:
                        separated = True
            rhs(t, y, f0, P, corners, PT, CS, stats)
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
