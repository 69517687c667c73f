# Kernel part: the stepping loop: steps, event detection, contact bookkeeping and output per step
# (stepping_loop), and the phase machine driven around it (advance, the entry point).
# Template text (see kernel/__init__.py): the imports above the marker are for
# linters and editors only: the generated module's header provides those names.
# flake8: noqa: F401,F403,F405
import math

import numpy as np

from ..dormand_prince import error_norm
from ..jit import jit, jit_leaf
from ..layout import *
from .events import event_values, locate
from .injected import *
from .output import emit_output, interpolate
from .phases import apply_event, record_point
from .rhs import contact_frequency, plate_displacement, rhs, surface_level
from .steps import EPS, initial_step, phase_tolerances, rosenbrock_now, trial_step
# --- template: equations.py copies what follows into the generated module ---


@jit
def advance(
    T,
    t_end,
    y,
    f,
    P,
    I,
    SURF,
    C,
    levels,
    tau_held,
    stats,
    trace,
    tcount,
    ev,
    evlog,
    O,
    out,
    y1,
    f1,
    err,
    work,
    y_root,
    f_tmp,
    K,
    W,
    g0,
    g1,
    g_tmp,
    JW,
    y_prev,
    scratch,
):
    """Integrate from T[T_TIME] to t_end with step T[T_STEP]; y, f updated in place.
    T[T_STALE] != 0 asks for f to be recomputed first (new phase, new command); T[T_STEP] <= 0
    for a fresh step size. With O[O_DT] = dt > 0, rows of ``out`` are written at the output times k dt (``emit_output``)
    from each step's continuous extension; contact steps end on those times, so the impulse
    of each output period is exact.

    Every located switch is applied here (``apply_event``) and logged in ``evlog`` (row
    ev[EV_COUNT], layout E_*): the phase machine costs no return to Python. Returns DONE at
    t_end, EVENT right after an event whose kind bit is in ev[EV_MASK], EVENT_LOG_FULL,
    TRACE_FULL or OUTPUT_FULL when a buffer needs draining, STEP_BUDGET after ev[EV_STEPS]
    steps (the caller regains control: Ctrl-C, its run budget), or an ERR_* status
    (ERR_RESIDUAL at a maximum compression that ``apply_event`` refused, not logged)."""
    size = y.shape[0]
    ns = SURF.shape[0]
    # y1 ... scratch: the stepping loop's scratch, allocated once by the caller
    # (``integrator.scratch_arrays``; separate arguments, not a tuple, so that numba's
    # dispatcher types them on its fast path): the kernel allocates nothing, so it needs no
    # reference-counting runtime (loading that runtime cost every process 20-30 ms)
    JW[JW.shape[0] - 1, 0] = 0.0  # no Jacobian yet (Rosenbrock)
    while True:
        status = stepping_loop(
            T,
            t_end,
            y,
            f,
            P,
            I,
            SURF,
            C,
            levels,
            tau_held,
            stats,
            trace,
            tcount,
            ev,
            y1,
            f1,
            err,
            work,
            y_root,
            f_tmp,
            K,
            W,
            g0,
            g1,
            g_tmp,
            JW,
            O,
            out,
            y_prev,
            scratch,
        )
        if status != EVENT:
            return status
        slot = ev[EV_SLOT]
        row = evlog[ev[EV_COUNT]]
        surface = slot if slot < ns else C[C_SURF]
        if not apply_event(slot, T[T_TIME], y, P, I, SURF, C, levels, row[E_INFO:E_Y]):
            return ERR_RESIDUAL
        row[E_SLOT], row[E_SURF], row[E_T] = slot, surface, T[T_TIME]
        for i in range(size):
            row[E_Y + i] = y[i]
        ev[EV_COUNT] += 1
        T[T_STALE] = 1.0  # the right-hand side changed with the phase
        JW[JW.shape[0] - 1, 0] = 0.0  # and so did its Jacobian (Rosenbrock)
        kind_bit = KIND_BIT_CONTACT if slot < ns else 1 << (1 + slot - ns)
        if slot < ns or slot - ns == EV_SEP or slot - ns == EV_SWITCH:
            # and so did its time scale (or, at a switch, the control target jumped): choose
            # a new step. Across yield and maximum compression the force is (nearly)
            # continuous, so the last step size carries over (saves the start-up
            # rejections: ~2-3 % fewer evaluations)
            T[T_STEP] = 0.0
        if ev[EV_MASK] & kind_bit:
            return EVENT
        if ev[EV_COUNT] >= evlog.shape[0]:
            return EVENT_LOG_FULL


# Longest contact step, as h ω <= CONTACT_RESOLUTION with ω the contact's normal frequency
# (``contact_frequency``). Why: Dormand-Prince's embedded error estimate is an asymptotic one;
# a step spanning most of a phase (at a loose contact tolerance the step carried over from
# the compression crossed the whole restitution, h ω ~ 2) passes the error test while its
# real error is ~100x the estimate: the article's fast sweep setting got every limit-cycle
# impact's CoR 6 % wrong that way (docs/benchmarks.md). A tolerance-independent cap keeps
# the estimate honest; tight tolerances take shorter steps anyway and are unchanged by it.
CONTACT_RESOLUTION = 0.5


@jit_leaf
def contact_step_cap(y, P, SURF, C, levels, scratch):
    """The longest contact step at state y (``CONTACT_RESOLUTION``); inf without force."""
    omega = contact_frequency(y, P, SURF, C, levels, scratch)
    return CONTACT_RESOLUTION / omega if omega > 0.0 else math.inf


@jit_leaf
def copy_into(dst, src):
    """dst[:] = src (a slice assignment may allocate a temporary, which needs NRT)."""
    for i in range(dst.shape[0]):
        dst[i] = src[i]


@jit
def stepping_loop(
    T,
    t_end,
    y,
    f,
    P,
    I,
    SURF,
    C,
    levels,
    tau_held,
    stats,
    trace,
    tcount,
    ev,
    y1,
    f1,
    err,
    work,
    y_root,
    f_tmp,
    K,
    W,
    g0,
    g1,
    g_tmp,
    JW,
    O,
    out,
    y_prev,
    scratch,
):
    """``advance`` with its scratch arrays."""
    output = O[O_DT] > 0.0
    # the phase, hence the step method, stays the same through one call (a switch returns)
    in_contact = int(C[C_PHASE]) != FREE
    quartic = not rosenbrock_now(I, C)  # Dormand-Prince steps carry a quartic extension
    ns = SURF.shape[0]
    rtol, atol = phase_tolerances(P, C)
    max_step = P[P_MAXSTEP]
    t = T[T_TIME]
    cap = contact_step_cap(y, P, SURF, C, levels, scratch) if in_contact else math.inf
    if T[T_STALE] != 0.0:
        rhs(t, y, f, P, I, SURF, C, levels, tau_held, stats, W)
        T[T_STALE] = 0.0
    if T[T_STEP] <= 0.0:
        T[T_STEP] = initial_step(t, y, f, P, I, SURF, C, levels, tau_held, stats, W, work, f1)
    h = T[T_STEP]
    event_values(y, P, I, SURF, C, levels, g0)
    eps4 = 4 * EPS * max(1.0, abs(t_end))
    # step-size exponent: 1 / (order of the error estimate + 1)
    expo = 0.2 if quartic else 0.25
    jac_valid = JW.shape[0] - 1
    status = DONE
    steps_left = ev[EV_STEPS]
    while t < t_end:
        steps_left -= 1
        if steps_left < 0:
            status = STEP_BUDGET
            break
        remaining = t_end - t
        if remaining <= eps4:
            t = t_end
            break
        step = min(h, max_step, cap)
        t_stop = t_end
        if output and in_contact:
            # in contact, steps end on the output times: each period's impulse is exact
            t_stop = min(t_end, O[O_NEXT] * O[O_DT])
            remaining = t_stop - t
        clipped = step >= remaining
        if clipped:
            step = remaining
        trial_step(
            t, y, f, step, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W, JW
        )
        norm = error_norm(err, y, y1, rtol, atol)
        if not norm <= 1.0:  # also catches NaN
            stats[ST_REJECTED] += 1
            if math.isfinite(norm):
                h = step * max(0.2, 0.9 * norm**-expo)
            else:
                h = step * 0.2
            if h < 1e-15 * max(1.0, abs(t)):
                status = ERR_NONFINITE if not math.isfinite(norm) else ERR_UNDERFLOW
                break
            continue
        stats[ST_STEPS] += 1
        factor = 5.0 if norm == 0.0 else min(5.0, max(0.2, 0.9 * norm**-expo))
        h = min(h, step * factor) if clipped else step * factor
        event_values(y1, P, I, SURF, C, levels, g1)
        best_s = step + 1.0
        best_k = last_k = -1
        for k in range(ns + 4):
            if g0[k] < 0.0 <= g1[k]:
                s_k = locate(
                    t,
                    y,
                    f,
                    step,
                    k,
                    g0[k],
                    g1[k],
                    y_root,
                    f_tmp,
                    err,
                    K,
                    work,
                    g_tmp,
                    P,
                    I,
                    SURF,
                    C,
                    levels,
                    tau_held,
                    stats,
                    W,
                    JW,
                )
                last_k = k
                if s_k < best_s:
                    best_s, best_k = s_k, k
        if best_k >= 0:
            copy_into(y_prev, y)
            if best_s < step:
                # locate() leaves the step to its root in y_root, f_tmp and K: take it again
                # only when a later slot's search overwrote them
                if last_k != best_k:
                    trial_step(
                        t,
                        y,
                        f,
                        best_s,
                        y_root,
                        f_tmp,
                        err,
                        K,
                        work,
                        P,
                        I,
                        SURF,
                        C,
                        levels,
                        tau_held,
                        stats,
                        W,
                        JW,
                    )
                copy_into(y, y_root)
                end_f = f_tmp
            else:
                copy_into(y, y1)
                end_f = f1
            t_prev = t
            t = t + best_s
            # the quartic needs this step's stages; locate() overwrote them if best_s == step
            own_stages = quartic and best_s < step
            if in_contact:
                interpolate(
                    t_prev,
                    best_s,
                    t_prev + 0.5 * best_s,
                    y_prev,
                    f,
                    y,
                    end_f,
                    K,
                    own_stages,
                    work,
                    0,
                )
                record_point(t, y, P, I, SURF, C, levels, trace, tcount, work)
            if output and not emit_output(
                t_prev,
                best_s,
                y_prev,
                f,
                y,
                end_f,
                K,
                own_stages,
                P,
                I,
                C,
                tau_held,
                O,
                out,
                scratch,
            ):
                status = OUTPUT_FULL
                break
            ev[EV_SLOT] = best_k
            status = EVENT
            break
        if in_contact or output:
            copy_into(y_prev, y)
            copy_into(y_root, f)  # the step's start derivative, for the midpoint and output
        copy_into(y, y1)
        copy_into(f, f1)
        JW[jac_valid, 0] = 0.0  # a new point: the Jacobian is due again
        t_prev = t
        t = t_stop if clipped else t + step
        if t == t_prev:  # a step below the resolution of t (max_step ~ 1e-300)
            status = ERR_UNDERFLOW
            break
        copy_into(g0, g1)
        delta = 0.0
        if in_contact:
            # the midpoint state for Simpson's impulse, from the step's extension
            interpolate(
                t_prev, t - t_prev, 0.5 * (t_prev + t), y_prev, y_root, y, f, K, quartic, work, 0
            )
            delta = record_point(t, y, P, I, SURF, C, levels, trace, tcount, work)
            cap = contact_step_cap(y, P, SURF, C, levels, scratch)
        else:
            # the dent is forgotten once the tip has risen above the surface again
            y_tip = tip(y[:N], y[N : 2 * N], P[P_L : P_L + NL])[1]
            for s in range(ns):
                # on a mounted surface, above its rest height in the plate's frame
                plate = plate_displacement(y, SURF, s) if HAS_MOUNT else 0.0
                if levels[s] != SURF[s, S_H] and y_tip - plate > SURF[s, S_H]:
                    levels[s] = SURF[s, S_H]
                    g0[s] = surface_level(y, SURF, levels, s) - y_tip
        # output after the step's impulse is booked, before any early return
        if output and not emit_output(
            t_prev, t - t_prev, y_prev, y_root, y, f, K, quartic, P, I, C, tau_held, O, out, scratch
        ):
            status = OUTPUT_FULL
            break
        if in_contact:
            if delta > SURF[int(C[C_SURF]), S_R]:
                status = ERR_PENETRATION
                break
            if tcount[0] >= trace.shape[0]:
                status = TRACE_FULL
                break
    T[T_TIME] = t
    T[T_STEP] = h
    return status
